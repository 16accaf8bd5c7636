"""Legs: the drive a place was recorded on (the place before it and the odometry positions
between), stored with the place, all or nothing, and copied to replicas."""

from __future__ import annotations

import dataclasses
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from mapdb_helpers import make_fingerprint, new_place, table_counts

from mapdb.database import MapDatabase
from mapdb.errors import UnknownPlaceError
from mapdb.records import MAX_VIA_POINTS, Leg, NewPlace
from mapdb.replica import apply_changes, read_changes, read_snapshot, write_snapshot
from mapdb.replication import (
    BadMapDataError,
    MapChange,
    MapRows,
    decode_changes,
    encode_changes,
    encode_snapshot,
)
from mapdb.schema import SCHEMA_VERSION


def on_a_drive(index: int, leg: Leg) -> NewPlace:
    return dataclasses.replace(new_place("hall", index), leg=leg)


def test_a_place_keeps_the_leg_it_was_recorded_on(map_db: MapDatabase, rng) -> None:
    first = map_db.add_place(new_place("office", 1), [make_fingerprint(rng)])
    second = map_db.add_place(
        on_a_drive(2, Leg(first, ((1.0, 0.5), (1.5, 0.0)))), [make_fingerprint(rng)]
    )
    stored = {place.id: place for place in map_db.places()}
    assert stored[first].leg is None
    assert stored[second].leg == Leg(first, ((1.0, 0.5), (1.5, 0.0)))
    assert map_db.place(second).leg == stored[second].leg


def test_a_leg_from_a_place_the_map_lacks_writes_nothing(map_db: MapDatabase, rng) -> None:
    map_db.add_place(new_place("office", 1), [make_fingerprint(rng)])
    with pytest.raises(UnknownPlaceError, match=r"starts at place 7, which .* does not have"):
        map_db.add_place(on_a_drive(2, Leg(7)), [make_fingerprint(rng)])
    assert table_counts(map_db.path)["places"] == 1
    assert table_counts(map_db.path)["legs"] == 0


def test_a_leg_from_a_place_without_a_position_is_refused(map_db: MapDatabase, rng) -> None:
    unplaced = NewPlace("office", f"{1:064x}", "carried there")
    first = map_db.add_place(unplaced, [make_fingerprint(rng)])
    with pytest.raises(ValueError, match=f"place {first}, which has no position"):
        map_db.add_place(on_a_drive(2, Leg(first)), [make_fingerprint(rng)])
    assert table_counts(map_db.path)["places"] == 1


def test_a_place_on_a_leg_needs_its_own_position() -> None:
    with pytest.raises(ValueError, match="needs its odometry position"):
        NewPlace("hall", f"{2:064x}", "s", leg=Leg(1))


@pytest.mark.parametrize(
    ("leg", "message"),
    [
        (lambda: Leg(0), "place id >= 1"),
        (lambda: Leg(True), "must be a place id"),  # type: ignore[arg-type]
        (lambda: Leg(1, ((0.0, float("nan")),)), "via point 0 must be two finite numbers"),
        (lambda: Leg(1, ((0.0, 1.0), (2.0,))), "via point 1 must be two finite numbers"),
        (lambda: Leg(1, ((0.0, 0.0),) * (MAX_VIA_POINTS + 1)), "more than"),
    ],
)
def test_a_malformed_leg_is_refused(leg, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        leg()


def test_a_replica_receives_the_legs_of_new_places(tmp_path: Path, rng) -> None:
    with MapDatabase.open(tmp_path / "site.db") as site:
        first = site.add_place(new_place("office", 1), [make_fingerprint(rng)])
        replica = tmp_path / "robot.db"
        write_snapshot(replica, encode_snapshot(read_snapshot(site)), str(site.map_id()))
        site.add_place(on_a_drive(2, Leg(first, ((3.0, 4.0),))), [make_fingerprint(rng)])
        map_id, changes = decode_changes(encode_changes(str(site.map_id()), read_changes(site, 1)))
        apply_changes(replica, map_id, changes)
        with MapDatabase.open(replica, readonly=True) as copy:
            assert [p.leg for p in copy.places()] == [None, Leg(first, ((3.0, 4.0),))]
            assert read_snapshot(copy) == read_snapshot(site)


def test_a_leg_whose_via_points_do_not_decode_is_refused() -> None:
    bad = MapChange(1, "place", MapRows(legs=((2, 1, '[[0, "x"]]'),)))
    with pytest.raises(BadMapDataError, match="legs row 0: leg via point 0"):
        decode_changes(encode_changes("map-1", [bad]))


def test_a_version_3_map_read_only_has_no_legs(db_path: Path, rng) -> None:
    with MapDatabase.open(db_path) as map_db:
        map_db.add_place(new_place("office", 1), [make_fingerprint(rng)])
    with sqlite3.connect(db_path) as conn:  # as the map was before legs
        conn.execute("DROP TABLE legs")
        conn.execute("ALTER TABLE fingerprints DROP COLUMN keypoint_sizes_px")
        conn.execute("UPDATE meta SET value = '3' WHERE key = 'schema_version'")
    with MapDatabase.open(db_path, readonly=True) as old:
        assert [p.leg for p in old.places()] == [None]
    with MapDatabase.open(db_path) as migrated:
        assert migrated.schema_version() == SCHEMA_VERSION
        assert table_counts(db_path)["legs"] == 0


def test_via_points_come_back_as_stored(map_db: MapDatabase, rng) -> None:
    first = map_db.add_place(new_place("office", 1), [make_fingerprint(rng)])
    via = tuple((float(x), float(y)) for x, y in np.random.default_rng(3).normal(size=(50, 2)))
    second = map_db.add_place(on_a_drive(2, Leg(first, via)), [make_fingerprint(rng)])
    assert map_db.place(second).leg == Leg(first, via)
