"""Opening map files: creation, WAL and foreign keys, migrations, and files we must not touch."""

from __future__ import annotations

import hashlib
import sqlite3
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import sqlite_utils
from mapdb_helpers import make_fingerprint, new_place, table_counts

from mapdb.database import MapDatabase
from mapdb.errors import (
    MapFileNotFoundError,
    NotAMapDatabaseError,
    SchemaVersionError,
)
from mapdb.schema import MIGRATIONS, SCHEMA_VERSION, read_schema_version


def file_digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_new_map_has_schema_version_wal_and_foreign_keys(map_db: MapDatabase) -> None:
    assert map_db.schema_version() == SCHEMA_VERSION == len(MIGRATIONS)
    assert map_db.db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert map_db.db.execute("PRAGMA foreign_keys").fetchone()[0] == 1
    assert {"meta", "rooms", "edges", "places", "fingerprints"} <= set(map_db.db.table_names())


def test_foreign_keys_are_enforced(map_db: MapDatabase) -> None:
    with pytest.raises(sqlite3.IntegrityError):
        map_db.db.execute(
            "INSERT INTO places (room_id, image_sha256, image_width_px, image_height_px, "
            "source, added_utc) VALUES (999, 'x', 1, 1, 's', 't')"
        )


def test_reopening_keeps_data_and_version(filled_map: MapDatabase, db_path: Path) -> None:
    filled_map.close()
    with MapDatabase.open(db_path) as again:
        assert again.schema_version() == SCHEMA_VERSION
        assert len(again.places()) == 3


def test_empty_existing_file_becomes_a_map(tmp_path: Path) -> None:
    path = tmp_path / "empty.db"
    path.touch()
    with MapDatabase.open(path) as map_db:
        assert map_db.schema_version() == SCHEMA_VERSION


def test_missing_file_without_create_names_it(tmp_path: Path) -> None:
    path = tmp_path / "nope.db"
    with pytest.raises(MapFileNotFoundError, match=r"nope\.db does not exist"):
        MapDatabase.open(path, create=False)
    assert not path.exists()


def test_newer_schema_is_refused_without_change(filled_map: MapDatabase, db_path: Path) -> None:
    filled_map.db.execute("UPDATE meta SET value = '99' WHERE key = 'schema_version'")
    filled_map.close()
    before = file_digest(db_path)
    for readonly in (False, True):
        with pytest.raises(SchemaVersionError, match=r"map\.db has map schema version 99"):
            MapDatabase.open(db_path, readonly=readonly)
    assert file_digest(db_path) == before
    with sqlite3.connect(db_path) as conn:
        assert (
            conn.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone()[0]
            == "99"
        )
    assert table_counts(db_path)["places"] == 3


@pytest.mark.parametrize(
    "content", [b"hello, this is not a database\n" * 50, bytes(range(256)) * 8]
)
def test_not_sqlite_file_is_refused_without_change(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "notes.db"
    path.write_bytes(content)
    with pytest.raises(NotAMapDatabaseError, match=r"notes\.db is not a valid SQLite database"):
        MapDatabase.open(path)
    assert path.read_bytes() == content


def test_foreign_sqlite_database_is_refused_without_change(tmp_path: Path) -> None:
    path = tmp_path / "other.db"
    with sqlite3.connect(path) as conn:
        conn.execute("CREATE TABLE customers (id INTEGER PRIMARY KEY, name TEXT)")
    conn.close()
    before = file_digest(path)
    with pytest.raises(NotAMapDatabaseError, match=r"other\.db is an SQLite database but not"):
        MapDatabase.open(path)
    assert file_digest(path) == before


def test_migrations_run_in_order_from_an_older_version(db_path: Path) -> None:
    with MapDatabase.open(db_path) as map_db:
        map_db.add_room("kitchen")

    def v2_add_notes(db: sqlite_utils.Database) -> None:
        db["rooms"].add_column("notes", str)

    migrations = (*MIGRATIONS, v2_add_notes)
    with MapDatabase.open(db_path, migrations=migrations) as map_db:
        assert map_db.schema_version() == len(MIGRATIONS) + 1
        assert "notes" in map_db.db["rooms"].columns_dict
        assert [room.name for room in map_db.rooms()] == ["kitchen"]
    # the current code now sees a newer file
    with pytest.raises(SchemaVersionError, match="newer"):
        MapDatabase.open(db_path)


def test_failing_migration_rolls_back_to_previous_version(db_path: Path) -> None:
    MapDatabase.open(db_path).close()

    def v2_broken(db: sqlite_utils.Database) -> None:
        db["rooms"].add_column("half_done", str)
        raise RuntimeError("migration bug")

    with pytest.raises(RuntimeError, match="migration bug"):
        MapDatabase.open(db_path, migrations=(*MIGRATIONS, v2_broken))
    with MapDatabase.open(db_path) as map_db:
        assert map_db.schema_version() == SCHEMA_VERSION
        assert "half_done" not in map_db.db["rooms"].columns_dict


def test_readonly_open_of_older_schema_asks_for_migration(db_path: Path) -> None:
    MapDatabase.open(db_path).close()
    extra = (*MIGRATIONS, lambda db: None)
    with pytest.raises(SchemaVersionError, match="older"):
        MapDatabase.open(db_path, readonly=True, migrations=extra)


def test_read_schema_version_of_empty_database_is_zero(tmp_path: Path) -> None:
    db = sqlite_utils.Database(tmp_path / "blank.db")
    assert read_schema_version(db) == 0


def test_a_version_1_map_opens_and_its_places_are_cylinders(
    db_path: Path, rng: np.random.Generator
) -> None:
    with MapDatabase.open(db_path, migrations=MIGRATIONS[:1]) as old:
        old.db.execute(
            "INSERT INTO rooms (name, created_utc) VALUES ('hall', '2026-01-01T00:00:00Z')"
        )
        old.db.execute(
            "INSERT INTO places (room_id, image_sha256, image_width_px, image_height_px, source, "
            "added_utc) VALUES (1, ?, 1024, 192, 'old.png', '2026-01-01T00:00:00Z')",
            ["a" * 64],
        )
        old.db.conn.commit()
    with MapDatabase.open(db_path) as map_db:
        assert map_db.schema_version() == SCHEMA_VERSION
        (place,) = map_db.places()
        assert (place.source, place.camera) == ("old.png", "cylinder")
        fingerprint = replace(make_fingerprint(rng, "sift", 5), params={"camera": "equirect"})
        new_id = map_db.add_place(new_place("hall", 7), [fingerprint])
        assert map_db.place(new_id).camera == "equirect"


def test_a_version_4_map_keeps_its_places_without_keypoint_sizes(
    db_path: Path, rng: np.random.Generator
) -> None:
    from mapdb.loading import load_fingerprint_table

    with MapDatabase.open(db_path) as old:
        old.add_place(new_place("hall", 1), [make_fingerprint(rng, "sift", 5, sizes=False)])
    with sqlite3.connect(db_path) as conn:  # as the map was before the sizes
        conn.execute("ALTER TABLE fingerprints DROP COLUMN keypoint_sizes_px")
        conn.execute("UPDATE meta SET value = '4' WHERE key = 'schema_version'")
    with MapDatabase.open(db_path, readonly=True) as read_only:
        assert load_fingerprint_table(read_only, "sift").fingerprint(0).keypoint_sizes_px is None
    with MapDatabase.open(db_path) as map_db:
        assert map_db.schema_version() == SCHEMA_VERSION
        map_db.add_place(new_place("hall", 2), [make_fingerprint(rng, "sift", 7)])
        assert map_db.info().fingerprints_without_sizes == 1
        table = load_fingerprint_table(map_db, "sift")
        assert table.fingerprint(0).keypoint_sizes_px is None
        sizes = table.fingerprint(1).keypoint_sizes_px
        assert sizes is not None and sizes.shape == (7,)
