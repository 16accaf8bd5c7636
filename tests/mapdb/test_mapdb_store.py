"""The on-disk place store: the same fingerprints as the table in memory, read on demand, a few
kept, and one-line errors for a blob that does not decode or a fingerprint gone since loading."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pytest
from mapdb_helpers import make_fingerprint, new_place

from mapdb.database import MapDatabase
from mapdb.errors import MapDatabaseError
from mapdb.loading import load_fingerprint_table, load_snapshot
from mapdb.store import SqlitePlaceStore


@pytest.fixture
def five_places(db_path: Path, rng: np.random.Generator) -> Path:
    """Five places in two rooms, SIFT fingerprints of 8 to 24 keypoints (and one MSER)."""
    with MapDatabase.open(db_path) as map_db:
        for i, n in enumerate([12, 8, 24, 16, 9]):
            fingerprints = [make_fingerprint(rng, "sift", n)]
            if i == 2:
                fingerprints.append(make_fingerprint(rng, "mser", 5))
            map_db.add_place(new_place("kitchen" if i % 2 else "hall", i), fingerprints)
    return db_path


def test_store_on_disk_returns_the_fingerprints_the_table_holds(five_places: Path) -> None:
    store = SqlitePlaceStore.open(five_places, "sift")
    with MapDatabase.open(five_places, readonly=True) as map_db:
        table = load_fingerprint_table(map_db, "sift")
    np.testing.assert_array_equal(store.place_ids, table.place_ids)
    assert store.rooms == table.rooms
    np.testing.assert_array_equal(store.keypoint_counts, table.keypoint_counts)
    np.testing.assert_array_equal(store.alv_xy, table.alv_xy)
    np.testing.assert_array_equal(store.image_sizes_px, table.image_sizes_px)
    assert store.params == table.params and store.descriptor_dim == table.descriptor_dim == 128
    for i, got in zip([3, 0, 3, 4], store.fingerprints([3, 0, 3, 4]), strict=True):
        want = table.fingerprint(i)
        np.testing.assert_array_equal(got.descriptors, want.descriptors)
        np.testing.assert_array_equal(got.keypoints_xy, want.keypoints_xy)
        np.testing.assert_array_equal(got.bearings_rad, want.bearings_rad)
        np.testing.assert_array_equal(got.rays(), want.rays())
        assert got.camera == want.camera


def test_store_keeps_only_its_last_few_fingerprints(five_places: Path) -> None:
    store = SqlitePlaceStore.open(five_places, "sift", cache_places=2)
    store.fingerprints([0, 1])
    store.fingerprints([1, 0])
    assert store.reads == 2  # both kept
    store.fingerprint(2)  # 1, the least recently used, is dropped
    store.fingerprint(0)
    assert store.reads == 3
    store.fingerprint(1)
    assert store.reads == 4


def test_snapshot_keeps_a_big_map_on_disk(five_places: Path) -> None:
    assert isinstance(load_snapshot(five_places, "sift", on_disk_from=5).table, SqlitePlaceStore)
    assert not isinstance(
        load_snapshot(five_places, "sift", on_disk_from=6).table, SqlitePlaceStore
    )
    assert not isinstance(load_snapshot(five_places, "sift").table, SqlitePlaceStore)


def test_a_blob_that_does_not_decode_is_a_one_line_error_naming_the_place(
    five_places: Path,
) -> None:
    store = SqlitePlaceStore.open(five_places, "sift")
    place_id = int(store.place_ids[2])
    with sqlite3.connect(five_places) as conn:
        conn.execute(
            "UPDATE fingerprints SET descriptors = x'0102' WHERE place_id = ? AND detector = ?",
            (place_id, "sift"),
        )
    store.fingerprint(1)  # the others still read
    with pytest.raises(
        MapDatabaseError, match=f"sift fingerprint of place {place_id} does not decode"
    ) as error:
        store.fingerprint(2)
    assert "\n" not in str(error.value) and str(five_places) in str(error.value)
    with pytest.raises(MapDatabaseError, match=f"place {place_id} does not decode"):
        list(store.descriptor_batches())


def test_a_fingerprint_gone_since_loading_is_named(five_places: Path) -> None:
    store = SqlitePlaceStore.open(five_places, "sift")
    place_id = int(store.place_ids[4])
    with sqlite3.connect(five_places) as conn:
        conn.execute("DELETE FROM fingerprints WHERE place_id = ?", (place_id,))
    with pytest.raises(MapDatabaseError, match=f"place {place_id} is gone or was replaced"):
        store.fingerprint(4)


def test_descriptor_batches_stream_every_place_in_order(five_places: Path) -> None:
    store = SqlitePlaceStore.open(five_places, "sift")
    with MapDatabase.open(five_places, readonly=True) as map_db:
        table = load_fingerprint_table(map_db, "sift")
    batches = list(store.descriptor_batches(start=1, batch_places=2))
    assert [len(b) for b in batches] == [2, 2]
    streamed = [d for batch in batches for d in batch]
    for i, descriptors in enumerate(streamed, start=1):
        np.testing.assert_array_equal(descriptors, table.fingerprint(i).descriptors)
