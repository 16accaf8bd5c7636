"""Rooms, edges and places: all-or-nothing writes, and faults that must not damage the map."""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path

import numpy as np
import pytest
import sqlite_utils
from mapdb_helpers import assert_consistent, make_fingerprint, new_place, table_counts

from mapdb.database import DuplicatePlaceError, MapDatabase
from mapdb.errors import (
    DatabaseLockedError,
    DiskFullError,
    MapDatabaseError,
    ReadOnlyDatabaseError,
    UnknownPlaceError,
    UnknownRoomError,
)
from mapdb.loading import load_fingerprints


def test_add_place_stores_pose_size_and_fingerprints(
    map_db: MapDatabase, rng: np.random.Generator
) -> None:
    sift, mser = make_fingerprint(rng, "sift", 5), make_fingerprint(rng, "mser", 0)
    place_id = map_db.add_place(new_place("lab", 7), [sift, mser])
    (place,) = map_db.places()
    assert place.id == place_id
    assert (place.room, place.x_m, place.y_m, place.heading_deg) == ("lab", 7.0, -1.5, 90.0)
    assert (place.image_width_px, place.image_height_px) == (360, 40)
    assert place.image_sha256 == f"{7:064x}"
    assert map_db.fingerprint_counts() == {"mser": 1, "sift": 1}
    assert map_db.place_id_for_image(f"{7:064x}") == place_id


def test_stored_params_are_the_first_fingerprint_s_of_a_detector(
    map_db: MapDatabase, rng: np.random.Generator
) -> None:
    assert map_db.stored_params() is None  # no places yet
    sift, mser = make_fingerprint(rng, "sift", 5), make_fingerprint(rng, "mser", 3)
    map_db.add_place(new_place("lab", 7), [sift, mser])
    assert map_db.stored_params()["detector"] == "sift"  # the first written
    assert map_db.stored_params("mser")["detector"] == "mser"
    assert map_db.stored_params("orb") is None


def test_unknown_pose_is_stored_as_null(map_db: MapDatabase, rng: np.random.Generator) -> None:
    place = new_place("lab", 1)
    unknown = type(place)(room="lab", image_sha256=place.image_sha256, source="s")
    map_db.add_place(unknown, [make_fingerprint(rng)])
    (stored,) = map_db.places()
    assert (stored.x_m, stored.y_m, stored.heading_deg, stored.captured_utc) == (None,) * 4


def test_duplicate_image_is_refused_and_names_the_place(
    filled_map: MapDatabase, rng: np.random.Generator
) -> None:
    with pytest.raises(DuplicatePlaceError, match="already place 1") as caught:
        filled_map.add_place(new_place("hall", 0), [make_fingerprint(rng)])
    assert caught.value.place_id == 1
    assert len(filled_map.places()) == 3


@pytest.mark.parametrize(
    ("detectors", "message"),
    [((), "no fingerprints"), (("sift", "sift"), "repeats a detector")],
)
def test_invalid_fingerprint_sets_are_refused(
    map_db: MapDatabase, rng: np.random.Generator, detectors: tuple[str, ...], message: str
) -> None:
    fingerprints = [make_fingerprint(rng, d) for d in detectors]
    with pytest.raises(ValueError, match=message):
        map_db.add_place(new_place("lab", 1), fingerprints)
    assert map_db.places() == []


def test_failure_while_writing_fingerprints_leaves_no_half_place(
    filled_map: MapDatabase, db_path: Path, rng: np.random.Generator, monkeypatch
) -> None:
    before = table_counts(db_path)

    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(sqlite_utils.db.Table, "insert_all", interrupted)
    with pytest.raises(KeyboardInterrupt):
        filled_map.add_place(new_place("new room", 50), [make_fingerprint(rng)])
    assert table_counts(db_path) == before
    assert [room.name for room in filled_map.rooms()] == ["hall", "kitchen"]
    assert_consistent(db_path)


def test_rooms_count_their_places(filled_map: MapDatabase) -> None:
    filled_map.add_room("attic")
    summary = {room.name: room.n_places for room in filled_map.rooms()}
    assert summary == {"attic": 0, "hall": 1, "kitchen": 2}
    assert [p.room for p in filled_map.places("kitchen")] == ["kitchen", "kitchen"]


def test_connect_rooms_is_undirected_and_idempotent(filled_map: MapDatabase) -> None:
    filled_map.add_room("attic")
    assert filled_map.connect_rooms("hall", "attic") is True
    assert filled_map.connect_rooms("attic", "hall") is False
    assert filled_map.connect_rooms("hall", "kitchen") is False
    assert filled_map.edges() == [("attic", "hall"), ("hall", "kitchen")]


def test_connect_unknown_room_names_it_and_changes_nothing(
    filled_map: MapDatabase, db_path: Path
) -> None:
    before = table_counts(db_path)
    with pytest.raises(UnknownRoomError, match=r"unknown room 'cellar' in .*map\.db") as caught:
        filled_map.connect_rooms("kitchen", "cellar")
    assert caught.value.room == "cellar"
    with pytest.raises(ValueError, match="itself"):
        filled_map.connect_rooms("hall", "hall")
    assert table_counts(db_path) == before


def test_unknown_room_and_place_are_named(filled_map: MapDatabase) -> None:
    with pytest.raises(UnknownRoomError, match="'cellar'"):
        filled_map.places("cellar")
    assert filled_map.place(3).room == "hall"
    with pytest.raises(UnknownPlaceError, match=r"unknown place 42 in .*map\.db"):
        filled_map.place(42)


def test_info_summarises_the_map(filled_map: MapDatabase) -> None:
    info = filled_map.info()
    assert info.n_places == 3
    assert [(r.name, r.n_places) for r in info.rooms] == [("hall", 1), ("kitchen", 2)]
    assert info.fingerprints_per_detector == {"mser": 3, "sift": 3}
    assert info.edges == [("hall", "kitchen")]
    assert info.file_size_bytes > 0
    assert info.to_json()["edges"] == [["hall", "kitchen"]]


def test_write_to_readonly_open_is_a_clear_error(filled_map: MapDatabase, db_path: Path) -> None:
    filled_map.close()
    before = table_counts(db_path)
    with MapDatabase.open(db_path, readonly=True) as readonly:
        assert len(readonly.places()) == 3
        with pytest.raises(ReadOnlyDatabaseError, match=r"map\.db is read-only"):
            readonly.connect_rooms("kitchen", "hall")
        with pytest.raises(ReadOnlyDatabaseError):
            readonly.add_room("attic")
    assert table_counts(db_path) == before


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores file permissions")
def test_readonly_file_is_a_clear_error(filled_map: MapDatabase, db_path: Path, rng) -> None:
    filled_map.close()
    for path in db_path.parent.glob("map.db*"):
        path.chmod(0o444)
    try:
        with (
            pytest.raises(ReadOnlyDatabaseError, match=r"map\.db"),
            MapDatabase.open(db_path) as map_db,
        ):
            map_db.add_place(new_place("hall", 9), [make_fingerprint(rng)])
    finally:
        for path in db_path.parent.glob("map.db*"):
            path.chmod(0o644)
    assert table_counts(db_path)["places"] == 3


def test_locked_database_is_a_clear_error(
    filled_map: MapDatabase, db_path: Path, rng: np.random.Generator
) -> None:
    filled_map.close()
    before = table_counts(db_path)
    holder = sqlite3.connect(db_path, isolation_level=None)
    holder.execute("BEGIN IMMEDIATE")
    try:
        with MapDatabase.open(db_path, busy_timeout_s=0.05) as map_db:
            with pytest.raises(DatabaseLockedError, match=r"map\.db is locked"):
                map_db.add_place(new_place("hall", 9), [make_fingerprint(rng)])
            assert len(map_db.places()) == 3  # reading still works (WAL)
    finally:
        holder.execute("ROLLBACK")
        holder.close()
    assert table_counts(db_path) == before
    assert_consistent(db_path)


def test_full_disk_rolls_back_and_keeps_existing_data(
    filled_map: MapDatabase, db_path: Path, rng: np.random.Generator
) -> None:
    before = table_counts(db_path)
    stored_before = load_fingerprints(filled_map)
    page_count = filled_map.db.execute("PRAGMA page_count").fetchone()[0]
    filled_map.db.execute(f"PRAGMA max_page_count = {page_count}")
    big = [make_fingerprint(rng, "sift", 2000)]
    with pytest.raises(DiskFullError, match=r"no space left for .*map\.db") as caught:
        filled_map.add_place(new_place("attic", 77), big)
    assert isinstance(caught.value, MapDatabaseError)
    assert filled_map.places()[-1].id == 3
    filled_map.close()
    assert table_counts(db_path) == before
    assert_consistent(db_path)
    with MapDatabase.open(db_path) as reopened:
        stored_after = load_fingerprints(reopened)
        np.testing.assert_array_equal(
            stored_after[0].fingerprint.descriptors, stored_before[0].fingerprint.descriptors
        )
        reopened.add_place(new_place("attic", 77), big)  # without the limit it fits
        assert len(reopened.places()) == 4


def test_a_read_transaction_sees_one_moment(
    filled_map: MapDatabase, db_path: Path, rng: np.random.Generator
) -> None:
    before, edges_before = len(filled_map.places()), len(filled_map.edges())
    with MapDatabase.open(db_path, readonly=True) as reader, reader.reading():
        assert len(reader.places()) == before
        filled_map.add_place(new_place("new room", 51), [make_fingerprint(rng)])
        filled_map.connect_rooms("new room", "hall")
        assert len(reader.places()) == before  # the place committed meanwhile is not seen
        assert len(reader.edges()) == edges_before  # nor its edge
    with MapDatabase.open(db_path, readonly=True) as reader:
        assert (len(reader.places()), len(reader.edges())) == (before + 1, edges_before + 1)
