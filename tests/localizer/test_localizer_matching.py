import numpy as np
import pytest

from localizer.matching import (
    exact_in_float32,
    match_descriptors,
    ratio_test_pairs,
    two_nearest_by_product,
    two_nearest_opencv,
)


def _descriptors(n: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).random((n, 128), dtype=np.float32)


def test_a_shuffled_copy_matches_every_row_to_its_original():
    reference = _descriptors(50)
    order = np.random.default_rng(1).permutation(50)
    pairs = match_descriptors(reference[order], reference)
    assert len(pairs) == 50
    assert np.array_equal(order[pairs[:, 0]], pairs[:, 1])


def test_unrelated_descriptors_mostly_fail_the_ratio_test():
    pairs = match_descriptors(_descriptors(200, 2), _descriptors(200, 3), ratio=0.7)
    assert len(pairs) < 10


def test_two_query_rows_never_share_a_reference_row():
    reference = _descriptors(20)
    query = np.vstack([reference[:5], reference[:5] + 1e-4])
    pairs = match_descriptors(query, reference)
    assert len(np.unique(pairs[:, 1])) == len(pairs)


def test_empty_sides_give_no_matches():
    assert match_descriptors(np.zeros((0, 128), np.float32), _descriptors(5)).shape == (0, 2)
    assert match_descriptors(_descriptors(5), _descriptors(1)).shape == (0, 2)


def test_mismatched_widths_are_rejected_with_both_shapes():
    with pytest.raises(ValueError, match=r"\(3, 64\)"):
        match_descriptors(_descriptors(3)[:, :64], _descriptors(3))


def test_the_ratio_test_keeps_distinct_rows_and_the_closest_claim_of_a_reference_row():
    nearest = np.array([[3, 1], [3, 0], [2, -1], [5, 4], [6, 7]])
    distances = np.array([[0.2, 1.0], [0.1, 1.0], [0.1, np.inf], [0.9, 1.0], [0.3, 1.0]])
    pairs = ratio_test_pairs(nearest, distances, ratio=0.8)
    # row 0 loses reference row 3 to the closer row 1; row 2 has no second neighbour; row 3
    # is not distinct (0.9 >= 0.8 x 1.0)
    assert pairs.tolist() == [[1, 3], [4, 6]]


def test_the_ratio_test_of_no_rows_gives_no_pairs():
    pairs = ratio_test_pairs(np.zeros((0, 2), np.int64), np.zeros((0, 2)), ratio=0.8)
    assert pairs.shape == (0, 2) and pairs.dtype == np.int64


def _sift_like(rng: np.random.Generator, n: int, high: int = 256) -> np.ndarray:
    """Integer-valued float32 rows, as OpenCV's SIFT gives them (and the map stores them)."""
    return rng.integers(0, high, (n, 128)).astype(np.float32)


def test_integer_descriptors_take_the_exact_product_and_match_as_opencv_does():
    rng = np.random.default_rng(7)
    for case in range(200):
        reference = _sift_like(rng, int(rng.integers(2, 60)), high=int(rng.integers(2, 256)))
        query = _sift_like(rng, int(rng.integers(1, 60)), high=int(rng.integers(2, 256)))
        if case % 3 == 0:  # ties: repeated rows on both sides, and queries equal to references
            reference[1::2] = reference[0]
            query[: len(query) // 2] = reference[rng.integers(0, len(reference))]
        assert exact_in_float32(query, reference)
        nearest, distances = two_nearest_opencv(query, reference)
        np.testing.assert_array_equal(two_nearest_by_product(query, reference)[1], distances)
        slow = ratio_test_pairs(nearest, distances.astype(np.float64), 0.8)
        np.testing.assert_array_equal(match_descriptors(query, reference), slow)


def test_descriptors_not_exact_in_float32_are_matched_by_opencv():
    assert not exact_in_float32(_descriptors(5), _descriptors(5))  # fractions
    big = np.full((2, 128), 300.0, np.float32)  # squared norms summing past 2**24
    assert not exact_in_float32(big, big)
    assert exact_in_float32(big[:, :64], big[:, :64])
