import numpy as np
import pytest

from localizer.matching import match_descriptors


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
