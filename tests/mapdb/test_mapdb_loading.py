"""Reading fingerprints back: exact round trip, the stacked table against the per-row list."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mapdb_helpers import make_fingerprint, new_place

from mapdb.codec import (
    ParamsCache,
    fingerprint_from_row,
    fingerprint_to_row,
    stored_alv,
)
from mapdb.database import MapDatabase
from mapdb.loading import load_fingerprint_table, load_fingerprints
from mapdb.records import Fingerprint


def assert_same_fingerprint(loaded: Fingerprint, original: Fingerprint) -> None:
    assert loaded.detector == original.detector
    assert (loaded.image_width_px, loaded.image_height_px) == (
        original.image_width_px,
        original.image_height_px,
    )
    np.testing.assert_array_equal(loaded.keypoints_xy, original.keypoints_xy.astype(np.float32))
    np.testing.assert_array_equal(loaded.bearings_rad, original.bearings_rad)
    np.testing.assert_array_equal(loaded.descriptors, original.descriptors)
    assert dict(loaded.params) == dict(original.params)
    assert loaded.keypoints_xy.dtype == np.float32
    assert loaded.descriptors.dtype == np.float32
    assert loaded.descriptors.shape == original.descriptors.shape
    if original.keypoint_sizes_px is None:
        assert loaded.keypoint_sizes_px is None
    else:
        assert loaded.keypoint_sizes_px is not None
        np.testing.assert_array_equal(loaded.keypoint_sizes_px, original.keypoint_sizes_px)


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(0, 60),
    dim=st.sampled_from([1, 64, 128]),
    seed=st.integers(0, 2**32 - 1),
    sizes=st.booleans(),
)
def test_codec_round_trip_is_exact(n: int, dim: int, seed: int, sizes: bool) -> None:
    original = make_fingerprint(np.random.default_rng(seed), "sift", n, dim, sizes)
    row = fingerprint_to_row(original)
    loaded = fingerprint_from_row(
        row["detector"],
        original.image_width_px,
        original.image_height_px,
        row["n_keypoints"],
        row["descriptor_dim"],
        row["keypoints_xy"],
        row["bearings_rad"],
        row["descriptor_dtype"],
        row["descriptors"],
        ParamsCache()(row["params_json"]),
        row["keypoint_sizes_px"],
    )
    assert_same_fingerprint(loaded, original)
    np.testing.assert_allclose([row["alv_x"], row["alv_y"]], stored_alv(original.bearings_rad))


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-10.0, 10.0), max_size=30))
def test_alv_matches_a_plain_loop(bearings: list[float]) -> None:
    expected = [0.0, 0.0]
    for bearing in bearings:
        expected[0] += np.cos(bearing) / len(bearings)
        expected[1] += np.sin(bearing) / len(bearings)
    np.testing.assert_allclose(stored_alv(np.array(bearings)), expected, atol=1e-12)


def test_alv_of_known_bearings() -> None:
    np.testing.assert_allclose(stored_alv(np.zeros(3)), [1.0, 0.0])
    np.testing.assert_allclose(stored_alv(np.array([np.pi / 2])), [0.0, 1.0], atol=1e-15)
    np.testing.assert_allclose(stored_alv(np.array([0.0, np.pi])), [0.0, 0.0], atol=1e-15)


def test_database_round_trip_is_exact(map_db: MapDatabase, rng: np.random.Generator) -> None:
    originals = {}
    for index in range(4):
        fingerprints = [make_fingerprint(rng, "sift", 3 * index), make_fingerprint(rng, "mser", 5)]
        place_id = map_db.add_place(new_place(f"room{index % 2}", index), fingerprints)
        originals.update({(place_id, f.detector): f for f in fingerprints})
    loaded = load_fingerprints(map_db)
    assert len(loaded) == len(originals)
    for stored in loaded:
        original = originals[(stored.place_id, stored.fingerprint.detector)]
        assert_same_fingerprint(stored.fingerprint, original)
        np.testing.assert_allclose(stored.alv_xy, stored_alv(original.bearings_rad))
        assert stored.room == f"room{(stored.place_id - 1) % 2}"
    assert {s.fingerprint.detector for s in load_fingerprints(map_db, "mser")} == {"mser"}


def test_table_matches_the_per_row_list(filled_map: MapDatabase) -> None:
    for detector in ("sift", "mser"):
        rows = load_fingerprints(filled_map, detector)
        table = load_fingerprint_table(filled_map, detector)
        assert table.place_ids.tolist() == [s.place_id for s in rows]
        assert list(table.rooms) == [s.room for s in rows]
        for i, stored in enumerate(rows):
            span = slice(table.offsets[i], table.offsets[i + 1])
            np.testing.assert_array_equal(table.descriptors[span], stored.fingerprint.descriptors)
            np.testing.assert_array_equal(table.bearings_rad[span], stored.fingerprint.bearings_rad)
            np.testing.assert_array_equal(table.keypoints_xy[span], stored.fingerprint.keypoints_xy)
            np.testing.assert_array_equal(table.alv_xy[i], stored.alv_xy)
            assert (table.keypoint_place_index[span] == i).all()


def test_a_place_without_sizes_has_none_in_the_table_and_the_others_keep_theirs(
    map_db: MapDatabase, rng: np.random.Generator
) -> None:
    with_sizes = make_fingerprint(rng, "sift", 6)
    without = make_fingerprint(rng, "sift", 4, sizes=False)
    map_db.add_place(new_place("a", 1), [with_sizes])
    map_db.add_place(new_place("a", 2), [without])
    table = load_fingerprint_table(map_db, "sift")
    assert_same_fingerprint(table.fingerprint(0), with_sizes)
    assert table.fingerprint(1).keypoint_sizes_px is None
    assert table.subset([1]).fingerprint(0).keypoint_sizes_px is None
    assert_same_fingerprint(table.subset([1, 0]).fingerprint(1), with_sizes)


def test_table_of_unknown_detector_is_empty(filled_map: MapDatabase) -> None:
    table = load_fingerprint_table(filled_map, "orb")
    assert table.place_ids.shape == (0,)
    assert table.descriptors.shape[0] == 0
    assert table.offsets.tolist() == [0]
    assert table.alv_xy.shape == (0, 2)


def test_table_refuses_mixed_descriptor_sizes(map_db: MapDatabase, rng) -> None:
    map_db.add_place(new_place("a", 1), [make_fingerprint(rng, "sift", 3, 128)])
    map_db.add_place(new_place("a", 2), [make_fingerprint(rng, "sift", 3, 64)])
    with pytest.raises(ValueError, match="several sizes"):
        load_fingerprint_table(map_db, "sift")


def test_params_are_decoded_once_per_distinct_text(filled_map: MapDatabase) -> None:
    loaded = load_fingerprints(filled_map, "sift")
    assert len({id(s.fingerprint.params) for s in loaded}) == 1


def test_integral_descriptors_are_stored_as_bytes_and_load_back_equal(
    map_db: MapDatabase, rng: np.random.Generator
) -> None:
    sift = make_fingerprint(rng, "sift", 9)
    integral = replace(sift, descriptors=np.rint(sift.descriptors * 255))
    assert fingerprint_to_row(integral)["descriptor_dtype"] == "u1"
    assert len(fingerprint_to_row(integral)["descriptors"]) == 9 * 128
    assert fingerprint_to_row(sift)["descriptor_dtype"] == "f4"
    map_db.add_place(new_place("a", 1), [integral])
    map_db.add_place(new_place("a", 2), [sift])
    first, second = load_fingerprints(map_db)
    assert_same_fingerprint(first.fingerprint, integral)
    assert_same_fingerprint(second.fingerprint, sift)
    table = load_fingerprint_table(map_db, "sift")  # mixed storage
    np.testing.assert_array_equal(table.descriptors[:9], integral.descriptors)
    np.testing.assert_array_equal(table.descriptors[9:], sift.descriptors)
