"""A map's rows for its replicas, and a replica file kept from them (SQLite).

The map's side: :func:`read_snapshot` (the whole map at one version, in one read transaction)
and :func:`read_changes` (the rows each write after a version added, from the change log of
:mod:`mapdb.schema`). The replica's side: :func:`replica_state` (its map id and version),
:func:`write_snapshot` (the snapshot into a new file beside the replica, checked, then moved
over it in one ``os.replace``) and :func:`apply_changes` (in one transaction, contiguous
versions only). A replica of another map, one ahead of the map, changes out of order or data
that does not decode raise a one-line :class:`~mapdb.errors.ReplicaError`, and the replica is
left as it was. A replica uses SQLite's rollback journal, not WAL: it never has a ``-wal`` file,
so replacing it is replacing one file.
"""

from __future__ import annotations

import json
import os
import sqlite3
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import sqlite_utils

from mapdb.database import MapDatabase
from mapdb.errors import (
    MapDatabaseError,
    ReplicaError,
    UnknownVersionError,
    translate_sqlite_error,
)
from mapdb.replication import (
    COLUMNS,
    TABLES,
    BadMapDataError,
    MapChange,
    MapRows,
    Row,
    Snapshot,
    decode_snapshot,
)
from mapdb.schema import (
    CHANGES_TABLE,
    MAP_ID_KEY,
    MAP_VERSION_KEY,
    META_TABLE,
    SCHEMA_VERSION,
    migrate,
    read_schema_version,
)

LIKELIHOOD_PREFIX = "likelihood:"
MAX_CHANGES = 32
"""The most changes :func:`read_changes` returns at once (a client asks again for the rest)."""


@dataclass(frozen=True)
class ReplicaState:
    """Which map a file holds (``map_id``) and at which ``version``."""

    map_id: str
    version: int


def _select(table: str, where: str = "") -> str:
    names = ", ".join(name for name, _ in COLUMNS[table])
    return f"SELECT {names} FROM {table} {where}"


def _likelihoods(map_db: MapDatabase, detector: str | None = None) -> tuple[tuple[str, str], ...]:
    if detector is None:
        rows = map_db.db.execute(
            f"SELECT key, value FROM {META_TABLE} WHERE key LIKE ? ORDER BY key",
            [LIKELIHOOD_PREFIX + "%"],
        ).fetchall()
    else:
        rows = map_db.db.execute(
            f"SELECT key, value FROM {META_TABLE} WHERE key = ?", [LIKELIHOOD_PREFIX + detector]
        ).fetchall()
    return tuple((key[len(LIKELIHOOD_PREFIX) :], value) for key, value in rows)


def _state(map_db: MapDatabase) -> ReplicaState:
    map_id = map_db.map_id()
    if map_id is None:
        raise MapDatabaseError(
            f"{map_db.path} has no map id (schema version {map_db.schema_version()}): open it "
            "for writing once (e.g. toploc map info is not enough; toploc node map does it)",
            map_db.path,
        )
    return ReplicaState(map_id, map_db.map_version())


def read_snapshot(map_db: MapDatabase) -> Snapshot:
    """The whole map (every row of :data:`~mapdb.replication.TABLES` and the likelihoods) at
    its current version, read in one transaction."""
    try:
        with map_db.reading():
            state = _state(map_db)
            tables = {
                name: tuple(map_db.db.execute(_select(name, "ORDER BY rowid")).fetchall())
                for name in TABLES
            }
            rows = MapRows(**tables, likelihoods=_likelihoods(map_db))
    except sqlite3.Error as error:
        raise translate_sqlite_error(error, map_db.path) from error
    return Snapshot(state.map_id, state.version, rows)


def _rows_of(map_db: MapDatabase, kind: str, ref: dict[str, int | str]) -> MapRows:
    """The rows change ``kind`` (referring to ``ref``) added, as they are now."""
    execute = map_db.db.execute

    def rooms(*ids: object) -> tuple[Row, ...]:
        marks = ", ".join("?" * len(ids))
        return tuple(execute(_select("rooms", f"WHERE id IN ({marks}) ORDER BY id"), ids))

    if kind == "place":
        place_id = ref["place_id"]
        places = tuple(execute(_select("places", "WHERE id = ?"), [place_id]).fetchall())
        fingerprints = execute(
            _select("fingerprints", "WHERE place_id = ? ORDER BY id"), [place_id]
        )
        legs = execute(_select("legs", "WHERE place_id = ?"), [place_id])
        room_ids = [row[1] for row in places]
        return MapRows(
            rooms=rooms(*room_ids),
            places=places,
            fingerprints=tuple(fingerprints),
            legs=tuple(legs),
        )
    if kind == "room":
        return MapRows(rooms=rooms(ref["room_id"]))
    if kind == "edge":
        a, b = ref["room_a_id"], ref["room_b_id"]
        edges = execute(_select("edges", "WHERE room_a_id = ? AND room_b_id = ?"), [a, b])
        return MapRows(rooms=rooms(a, b), edges=tuple(edges))
    if kind == "likelihood":
        return MapRows(likelihoods=_likelihoods(map_db, str(ref["detector"])))
    raise MapDatabaseError(f"{map_db.path}: change log holds an unknown kind {kind!r}", map_db.path)


def read_changes(map_db: MapDatabase, after: int, limit: int = MAX_CHANGES) -> list[MapChange]:
    """The changes after version ``after`` (at most ``limit``, in order). Raises
    :class:`UnknownVersionError` for a version the map does not have (negative, or ahead)."""
    try:
        with map_db.reading():
            version = map_db.map_version()
            if isinstance(after, bool) or not isinstance(after, int) or not 0 <= after <= version:
                raise UnknownVersionError(
                    f"map {map_db.map_id()} has no version {after!r}: it is at version {version} "
                    "(a replica ahead of the map is of another map, or the map lost changes)",
                    map_db.path,
                )
            log = map_db.db.execute(
                f"SELECT version, kind, ref_json FROM {CHANGES_TABLE} WHERE version > ? "
                "ORDER BY version LIMIT ?",
                [after, limit],
            ).fetchall()
            return [
                MapChange(v, kind, _rows_of(map_db, kind, json.loads(ref))) for v, kind, ref in log
            ]
    except sqlite3.Error as error:
        raise translate_sqlite_error(error, map_db.path) from error


# --- the replica's side ---------------------------------------------------------------------


@contextmanager
def _replica_connection(path: Path) -> Iterator[sqlite_utils.Database]:
    """A connection to the replica file (rollback journal, foreign keys on), closed after."""
    conn = sqlite3.connect(str(path), isolation_level=None)
    db = sqlite_utils.Database(conn, execute_plugins=False)
    try:
        db.execute("PRAGMA busy_timeout = 5000")
        db.execute("PRAGMA journal_mode = DELETE")
        db.execute("PRAGMA foreign_keys = ON")
        yield db
    finally:
        db.close()


def replica_state(path: Path | str) -> ReplicaState | None:
    """The map id and version the replica at ``path`` holds; None if there is no file yet."""
    path = Path(path)
    if not path.exists():
        return None
    with MapDatabase.open(path, create=False, readonly=True) as map_db:
        return _state(map_db)


def _insert(db: sqlite_utils.Database, rows: MapRows, where: str) -> None:
    """Insert ``rows``; a room id that names another room, or a place already held, is a
    :class:`BadMapDataError` (the replica diverged)."""
    for row in rows.rooms:
        db.execute("INSERT OR IGNORE INTO rooms (id, name, created_utc) VALUES (?, ?, ?)", row)
        held = db.execute("SELECT name FROM rooms WHERE id = ?", [row[0]]).fetchone()
        if held is None or held[0] != row[1]:
            raise BadMapDataError(
                f"{where}: room {row[0]} is {row[1]!r} in the map but "
                f"{None if held is None else held[0]!r} here"
            )
    for table in ("places", "fingerprints", "legs", "edges"):
        names = [name for name, _ in COLUMNS[table]]
        verb = "INSERT OR IGNORE" if table == "edges" else "INSERT"
        sql = f"{verb} INTO {table} ({', '.join(names)}) VALUES ({', '.join('?' * len(names))})"
        for row in rows.table(table):
            try:
                db.execute(sql, row)
            except sqlite3.IntegrityError as error:
                raise BadMapDataError(f"{where}: {table} row {row[0]}: {error}") from None
    for detector, value in rows.likelihoods:
        db.execute(
            f"INSERT OR REPLACE INTO {META_TABLE} (key, value) VALUES (?, ?)",
            [LIKELIHOOD_PREFIX + detector, value],
        )


def _set_state(db: sqlite_utils.Database, state: ReplicaState) -> None:
    db.execute(
        f"INSERT OR REPLACE INTO {META_TABLE} (key, value) VALUES (?, ?), (?, ?)",
        [MAP_ID_KEY, state.map_id, MAP_VERSION_KEY, str(state.version)],
    )


def write_snapshot(path: Path | str, data: bytes, map_id: str) -> ReplicaState:
    """Make the file at ``path`` a replica of map ``map_id`` from the encoded snapshot
    ``data``: decoded and checked, written to a new file beside it, then moved over it at once
    (a replica there before is replaced whole, or kept whole on any error)."""
    path = Path(path)
    try:
        snapshot = decode_snapshot(data)
    except BadMapDataError as error:
        raise ReplicaError(f"replica {path}: snapshot refused: {error}", path) from None
    if snapshot.map_id != map_id:
        raise ReplicaError(
            f"replica {path}: the snapshot is of map {snapshot.map_id!r}, not {map_id!r}", path
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".new", dir=path.parent)
    os.close(handle)
    temp = Path(temp_name)
    try:
        with _replica_connection(temp) as db:
            migrate(db)
            db.execute("BEGIN IMMEDIATE")
            _insert(db, snapshot.rows, f"snapshot of version {snapshot.version}")
            _set_state(db, ReplicaState(map_id, snapshot.version))
            db.execute("COMMIT")
            if db.execute("PRAGMA integrity_check").fetchone()[0] != "ok":
                raise BadMapDataError("the written replica fails SQLite's integrity check")
        for suffix in ("-wal", "-shm", "-journal"):  # a former file's: never the new one's
            path.with_name(path.name + suffix).unlink(missing_ok=True)
        os.replace(temp, path)
    except BadMapDataError as error:
        raise ReplicaError(f"replica {path}: snapshot refused: {error}", path) from None
    except sqlite3.Error as error:
        raise translate_sqlite_error(error, path) from error
    finally:
        temp.unlink(missing_ok=True)
    return ReplicaState(map_id, snapshot.version)


def apply_changes(path: Path | str, map_id: str, changes: Sequence[MapChange]) -> ReplicaState:
    """Apply ``changes`` of map ``map_id`` to the replica at ``path`` in one transaction: they
    must be of its map and start right after its version, one version after another."""
    path = Path(path)
    state = replica_state(path)
    if state is None:
        raise ReplicaError(f"replica {path} does not exist: it starts from a snapshot", path)
    check_same_map(path, state, map_id)
    expected = state.version + 1
    for change in changes:
        if change.version != expected:
            raise ReplicaError(
                f"replica {path}: change out of order: version {change.version} where "
                f"{expected} comes next (the replica is at version {state.version})",
                path,
            )
        expected += 1
    if not changes:
        return state
    try:
        with _replica_connection(path) as db:
            if read_schema_version(db) != SCHEMA_VERSION:
                raise BadMapDataError(f"schema version {read_schema_version(db)}")
            db.execute("BEGIN IMMEDIATE")
            try:
                for change in changes:
                    _insert(db, change.rows, f"change {change.version} ({change.kind})")
                new_state = ReplicaState(map_id, changes[-1].version)
                _set_state(db, new_state)
                db.execute("COMMIT")
            except BaseException:
                db.execute("ROLLBACK")
                raise
    except BadMapDataError as error:
        raise ReplicaError(
            f"replica {path}: changes refused, none applied: {error}", path
        ) from None
    except sqlite3.Error as error:
        raise translate_sqlite_error(error, path) from error
    return new_state


def check_same_map(
    path: Path, state: ReplicaState, map_id: str, version: int | None = None
) -> None:
    """Raise :class:`ReplicaError` if the replica at ``path`` (``state``) is of another map
    than ``map_id``, or ahead of the map's ``version`` (when given): never merged."""
    if state.map_id != map_id:
        raise ReplicaError(
            f"replica {path} is of map {state.map_id!r}, not {map_id!r}: refused (delete it or "
            "give another --db to start a replica of this map)",
            path,
        )
    if version is not None and state.version > version:
        raise ReplicaError(
            f"replica {path} is at version {state.version}, ahead of map {map_id!r} at version "
            f"{version}: refused, not merged (the map lost changes, or was made again: delete "
            "the replica to start from the map's snapshot)",
            path,
        )
