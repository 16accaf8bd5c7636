"""The SQLite adapter: open a map file, migrate it, and read and write rooms, edges and places.

One :class:`MapDatabase` wraps one ``sqlite_utils.Database`` connection in WAL mode with foreign
keys on. Every write runs in a ``BEGIN IMMEDIATE`` transaction that either commits whole or
rolls back; every ``sqlite3`` error is re-raised as a :class:`~mapdb.errors.MapDatabaseError`
naming the file. Fast bulk reads of fingerprints live in :mod:`mapdb.loading`.
"""

from __future__ import annotations

import functools
import json
import sqlite3
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, ParamSpec, TypeVar
from urllib.parse import quote

import sqlite_utils

from mapdb.codec import fingerprint_to_row, leg_from_row, via_to_json
from mapdb.errors import (
    SQLITE_CANTOPEN,
    SQLITE_READONLY,
    DuplicatePlaceError,
    InvalidValueError,
    MapDatabaseError,
    MapFileNotFoundError,
    NotAMapDatabaseError,
    ReadOnlyDatabaseError,
    SchemaVersionError,
    UnknownPlaceError,
    UnknownRoomError,
    translate_sqlite_error,
)
from mapdb.records import Fingerprint, Leg, MapInfo, NewPlace, Place, RoomSummary, check_name
from mapdb.schema import (
    CHANGES_TABLE,
    MAP_ID_KEY,
    MAP_VERSION_KEY,
    META_TABLE,
    MIGRATIONS,
    READ_ONLY_VIEWS,
    SCHEMA_VERSION,
    Migration,
    migrate,
    read_schema_version,
)

_SELECT_PLACES = (
    "SELECT p.id, r.name, p.x_m, p.y_m, p.heading_deg, p.image_sha256, p.image_width_px, "
    "p.image_height_px, p.captured_utc, p.source, p.added_utc, p.camera, l.from_place_id, "
    "l.via_json FROM places p JOIN rooms r ON r.id = p.room_id "
    "LEFT JOIN legs l ON l.place_id = p.id"
)


def _place_from_row(row: Sequence[Any]) -> Place:
    """A :class:`Place` from a row of ``_SELECT_PLACES``."""
    *columns, from_place_id, via_json = row
    place = Place(*columns)
    if from_place_id is None:
        return place
    return replace(place, leg=leg_from_row(from_place_id, via_json))


P = ParamSpec("P")
R = TypeVar("R")


def utc_now_iso() -> str:
    """The current time as ISO-8601 UTC text with seconds."""
    return datetime.now(UTC).isoformat(timespec="seconds")


def _translated(method: Callable[P, R]) -> Callable[P, R]:
    """Re-raise ``sqlite3.Error`` from a :class:`MapDatabase` method as a MapDatabaseError."""

    @functools.wraps(method)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        try:
            return method(*args, **kwargs)
        except sqlite3.Error as error:
            self = args[0]
            assert isinstance(self, MapDatabase)
            raise translate_sqlite_error(error, self.path) from error

    return wrapper


_CANNOT_READ_IN_PLACE = (SQLITE_CANTOPEN, SQLITE_READONLY)
"""Codes of a ``mode=ro`` open that fails because a WAL map's ``-shm`` cannot be made."""


def _connect_readonly(path: Path) -> sqlite3.Connection:
    """A read-only connection, also to a map on read-only media.

    ``mode=ro`` first. A WAL map in a folder nobody may write to fails that way (SQLite needs
    its ``-shm`` file to read), so it is opened ``immutable=1``: no locks and no ``-shm``, which
    is safe because no one can change the file there. A leftover non-empty ``-wal`` (a writer
    that did not finish) would be ignored by ``immutable``, so that is a clear error instead.
    """
    uri = f"file:{quote(str(path.resolve()))}?mode=ro"
    conn = sqlite3.connect(uri, uri=True)
    try:
        conn.execute("SELECT COUNT(*) FROM sqlite_master").fetchone()
        return conn
    except sqlite3.Error as error:
        conn.close()
        if (getattr(error, "sqlite_errorcode", 0) or 0) & 0xFF not in _CANNOT_READ_IN_PLACE:
            raise
    wal = path.with_name(path.name + "-wal")
    if wal.exists() and wal.stat().st_size > 0:
        raise ReadOnlyDatabaseError(
            f"{path} cannot be read where it is: its folder is read-only and {wal.name} holds "
            f"writes not yet in the map; open it once on writable media (e.g. `toploc map "
            f"info` on a copy of both files)",
            path,
        )
    return sqlite3.connect(uri + "&immutable=1", uri=True)


def _connect(path: Path, readonly: bool, busy_timeout_s: float) -> sqlite_utils.Database:
    """Open the SQLite connection (read-only: :func:`_connect_readonly`), set its pragmas."""
    conn = _connect_readonly(path) if readonly else sqlite3.connect(str(path))
    db = sqlite_utils.Database(conn, execute_plugins=False)
    db.execute(f"PRAGMA busy_timeout = {int(busy_timeout_s * 1000)}")
    db.execute("PRAGMA foreign_keys = ON")
    return db


class MapDatabase:
    """An open map database. Use :meth:`open`; close it (or use ``with``) when done."""

    def __init__(self, db: sqlite_utils.Database, path: Path, readonly: bool) -> None:
        self.db = db
        self.path = path
        self.readonly = readonly

    @classmethod
    def open(
        cls,
        path: Path | str,
        *,
        create: bool = True,
        readonly: bool = False,
        busy_timeout_s: float = 5.0,
        migrations: Sequence[Migration] = MIGRATIONS,
    ) -> MapDatabase:
        """Open (and create, unless ``create`` is False) the map at ``path``, migrating it.

        Checks before writing anything: a file that is not SQLite or not a toploc map raises
        :class:`NotAMapDatabaseError`, a newer schema :class:`SchemaVersionError`; the file is
        left untouched. ``readonly`` opens with ``mode=ro`` (``immutable=1`` on read-only
        media) and never writes: an older schema is read through temporary views
        (:data:`mapdb.schema.READ_ONLY_VIEWS`).
        """
        path = Path(path)
        if (readonly or not create) and not path.exists():
            raise MapFileNotFoundError(f"map database {path} does not exist", path)
        if path.is_dir():
            raise MapDatabaseError(f"{path} is a directory, not a map database file", path)
        try:
            db = _connect(path, readonly, busy_timeout_s)
        except sqlite3.Error as error:
            raise translate_sqlite_error(error, path) from error
        try:
            cls._prepare(db, path, readonly, migrations)
        except sqlite3.Error as error:
            db.close()
            raise translate_sqlite_error(error, path) from error
        except BaseException:
            db.close()
            raise
        return cls(db, path, readonly)

    @staticmethod
    def _prepare(
        db: sqlite_utils.Database, path: Path, readonly: bool, migrations: Sequence[Migration]
    ) -> None:
        """Check the schema version, then (if writable) switch to WAL and migrate."""
        version = read_schema_version(db)
        known = len(migrations)
        if version is None:
            raise NotAMapDatabaseError(
                f"{path} is an SQLite database but not a toploc map (no valid schema version "
                f"in its 'meta' table)",
                path,
            )
        if version > known:
            raise SchemaVersionError(
                f"{path} has map schema version {version}, newer than this toploc supports "
                f"({known}); upgrade toploc to use it. The file was not changed.",
                path,
            )
        if readonly and version == 0:
            raise NotAMapDatabaseError(f"{path} is empty, not a toploc map", path)
        if readonly and version < known:
            views = [READ_ONLY_VIEWS.get(migration) for migration in migrations[version:]]
            if any(view is None for view in views):
                raise SchemaVersionError(
                    f"{path} has map schema version {version}, older than {known}; open it for "
                    f"writing once (e.g. `toploc map add` or `map connect`) to migrate it",
                    path,
                )
            for view in views:  # the newer schema in memory; the file is not changed
                db.execute(str(view))
        if not readonly:
            db.enable_wal()
            migrate(db, migrations)

    def close(self) -> None:
        """Close the connection; uncommitted work (there is none outside a transaction) is lost."""
        self.db.close()

    def __enter__(self) -> MapDatabase:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    @contextmanager
    def _in_transaction(self, begin: str) -> Iterator[None]:
        """``begin``, then COMMIT on success and ROLLBACK on any error; SQLite errors (including
        at ``COMMIT``, such as a full disk) are raised translated."""
        try:
            self.db.execute(begin)
            try:
                yield
                self.db.execute("COMMIT")
            except BaseException:
                if self.db.conn.in_transaction:
                    self.db.execute("ROLLBACK")
                raise
        except sqlite3.Error as error:
            raise translate_sqlite_error(error, self.path) from error

    @contextmanager
    def transaction(self) -> Iterator[sqlite_utils.Database]:
        """A write transaction (``BEGIN IMMEDIATE``): commits on success, rolls back on any error.

        SQLite errors (including at ``COMMIT``, such as a full disk) are raised translated.
        """
        with self._in_transaction("BEGIN IMMEDIATE"):
            yield self.db

    @contextmanager
    def reading(self) -> Iterator[MapDatabase]:
        """A read transaction: every read within sees the map as of one moment (a commit that
        lands meanwhile is seen whole after the block, not in part within it). Two writes
        (``map/add``, then ``map/connect``) are two commits: a snapshot may fall between them."""
        with self._in_transaction("BEGIN"):
            yield self

    @_translated
    def schema_version(self) -> int:
        """The schema version stored in the file."""
        return read_schema_version(self.db) or 0

    @_translated
    def likelihood(self, detector: str) -> dict[str, Any] | None:
        """The stored likelihood calibration of ``detector``'s evidence (JSON), or None."""
        row = self.db.execute(
            f"SELECT value FROM {META_TABLE} WHERE key = ?", [_likelihood_key(detector)]
        ).fetchone()
        if row is None:
            return None
        try:
            value = json.loads(row[0])
        except json.JSONDecodeError as error:
            raise MapDatabaseError(
                f"{self.path}: the stored likelihood of {detector!r} is not JSON ({error})",
                self.path,
            ) from None
        return value if isinstance(value, dict) else None

    @_translated
    def set_likelihood(self, detector: str, calibration: Mapping[str, Any]) -> None:
        """Store the likelihood calibration of ``detector`` (replacing an older one)."""
        with self.transaction():
            self.db.execute(
                f"INSERT OR REPLACE INTO {META_TABLE} (key, value) VALUES (?, ?)",
                [_likelihood_key(detector), json.dumps(dict(calibration), sort_keys=True)],
            )
            self._log_change("likelihood", {"detector": detector})

    def _meta(self, key: str) -> str | None:
        row = self.db.execute(f"SELECT value FROM {META_TABLE} WHERE key = ?", [key]).fetchone()
        return None if row is None else str(row[0])

    @_translated
    def map_version(self) -> int:
        """The map's version: the number of the last write in its change log (0: none since
        the map was made, or migrated to schema version 3)."""
        return int(self._meta(MAP_VERSION_KEY) or 0)

    @_translated
    def map_id(self) -> str | None:
        """The map's own id (what a replica of it checks); None for a map read-only and too old
        to have one (schema version < 3, not migrated)."""
        return self._meta(MAP_ID_KEY)

    def set_map_id(self, map_id: str) -> None:
        """Name the map ``map_id`` (one key chunk, :func:`~mapdb.records.check_name`); replicas
        made under its former id refuse it afterwards."""
        self._checked(map_id, "map id")
        if set("/*$?#") & set(map_id):
            raise InvalidValueError(
                f"map id {map_id!r} must not contain '/', '*', '$', '?' or '#' (map {self.path})",
                self.path,
            )
        with self.transaction():
            self.db.execute(
                f"INSERT OR REPLACE INTO {META_TABLE} (key, value) VALUES (?, ?)",
                [MAP_ID_KEY, map_id],
            )

    def _log_change(self, kind: str, ref: Mapping[str, Any]) -> int:
        """Give the write under way (call inside :meth:`transaction`) the next map version, in
        the change log: ``kind`` (place, room, edge, likelihood) and what it wrote; returns it
        (0 for a map opened with the migrations of an older schema, which has no log)."""
        if not self.db.table(CHANGES_TABLE).exists():
            return 0
        version = int(self._meta(MAP_VERSION_KEY) or 0) + 1
        self.db.execute(
            f"INSERT INTO {CHANGES_TABLE} (version, kind, ref_json, created_utc) "
            "VALUES (?, ?, ?, ?)",
            [version, kind, json.dumps(dict(ref), sort_keys=True), utc_now_iso()],
        )
        self.db.execute(
            f"INSERT OR REPLACE INTO {META_TABLE} (key, value) VALUES (?, ?)",
            [MAP_VERSION_KEY, str(version)],
        )
        return version

    def _room_id(self, name: str) -> int | None:
        row = self.db.execute("SELECT id FROM rooms WHERE name = ?", [name]).fetchone()
        return None if row is None else int(row[0])

    @_translated
    def room_id(self, name: str) -> int:
        """The id of room ``name``; raises :class:`UnknownRoomError` if there is none."""
        room_id = self._room_id(name)
        if room_id is None:
            raise UnknownRoomError(name, self.path)
        return room_id

    def _ensure_room(self, name: str) -> int:
        """Id of room ``name``, inserting it if new; call inside :meth:`transaction`."""
        room_id = self._room_id(name)
        if room_id is not None:
            return room_id
        table = self.db.table("rooms").insert({"name": name, "created_utc": utc_now_iso()})
        return _inserted_id(table)

    def _checked(self, name: str, what: str = "room name") -> str:
        """``name`` if :func:`~mapdb.records.check_name` takes it, else an
        :class:`InvalidValueError` naming this map."""
        try:
            return check_name(name, what)
        except ValueError as error:
            raise InvalidValueError(f"{error} (map {self.path})", self.path) from None

    def add_room(self, name: str) -> int:
        """Add room ``name`` if it is new (one transaction); return its id. Raises
        :class:`InvalidValueError` for a name :func:`~mapdb.records.check_name` refuses."""
        self._checked(name)
        with self.transaction():
            room_id = self._room_id(name)
            if room_id is None:
                room_id = self._ensure_room(name)
                self._log_change("room", {"room_id": room_id})
            return room_id

    @_translated
    def rooms(self) -> list[RoomSummary]:
        """All rooms by name, with their number of places."""
        rows = self.db.execute(
            "SELECT r.id, r.name, COUNT(p.id) FROM rooms r LEFT JOIN places p ON p.room_id = r.id "
            "GROUP BY r.id ORDER BY r.name"
        ).fetchall()
        return [RoomSummary(id=row[0], name=row[1], n_places=row[2]) for row in rows]

    def connect_rooms(self, room_a: str, room_b: str) -> bool:
        """Add the undirected edge between two existing rooms; False if it was already there.

        Raises :class:`UnknownRoomError` naming the first unknown room, ``ValueError`` for a
        self-loop, :class:`InvalidValueError` for a name no room can have.
        """
        self._checked(room_a)
        self._checked(room_b)
        if room_a == room_b:
            raise ValueError(f"cannot connect room {room_a!r} to itself")
        with self.transaction():
            ids = []
            for name in (room_a, room_b):
                room_id = self._room_id(name)
                if room_id is None:
                    raise UnknownRoomError(name, self.path)
                ids.append(room_id)
            low, high = sorted(ids)
            cursor = self.db.execute(
                "INSERT OR IGNORE INTO edges (room_a_id, room_b_id, created_utc) VALUES (?, ?, ?)",
                [low, high, utc_now_iso()],
            )
            if cursor.rowcount != 1:
                return False
            self._log_change("edge", {"room_a_id": low, "room_b_id": high})
            return True

    @_translated
    def edges(self) -> list[tuple[str, str]]:
        """All room-graph edges as pairs of room names, each pair sorted, sorted overall."""
        rows = self.db.execute(
            "SELECT a.name, b.name FROM edges e JOIN rooms a ON a.id = e.room_a_id "
            "JOIN rooms b ON b.id = e.room_b_id"
        ).fetchall()
        pairs = [(a, b) if a <= b else (b, a) for a, b in rows]
        return sorted(pairs)

    @_translated
    def place_id_for_image(self, image_sha256: str) -> int | None:
        """The place holding the image with this SHA-256, if any."""
        return self._place_id_for_image(image_sha256)

    @_translated
    def image_hashes(self) -> dict[str, int]:
        """Every stored image SHA-256 with its place id."""
        return dict(self.db.execute("SELECT image_sha256, id FROM places").fetchall())

    def add_place(self, place: NewPlace, fingerprints: Sequence[Fingerprint]) -> int:
        """Add a place with its fingerprints (one per detector) in one transaction; return its id.

        All or nothing: on any error (duplicate image, full disk, lock) nothing is written.
        Raises :class:`DuplicatePlaceError` if the image is already in the map, ``ValueError``
        for no fingerprints, repeated detectors, differing image sizes or a detector or camera
        name :func:`~mapdb.records.check_name` refuses (the place itself is checked by
        :class:`~mapdb.records.NewPlace`: room name, finite pose).
        """
        if not fingerprints:
            raise ValueError(f"place {place.source!r} has no fingerprints")
        detectors = [self._checked(f.detector, "detector name") for f in fingerprints]
        if len(set(detectors)) != len(detectors):
            raise ValueError(f"place {place.source!r} repeats a detector: {detectors}")
        sizes = {(f.image_width_px, f.image_height_px) for f in fingerprints}
        if len(sizes) != 1:
            raise ValueError(f"fingerprints of {place.source!r} disagree on image size: {sizes}")
        ((width_px, height_px),) = sizes
        cameras = {str(f.params.get("camera", "cylinder")) for f in fingerprints}
        if len(cameras) != 1:
            raise ValueError(f"fingerprints of {place.source!r} disagree on the camera: {cameras}")
        (camera,) = cameras
        self._checked(camera, "camera model")
        rows = [fingerprint_to_row(f) for f in fingerprints]
        with self.transaction():
            existing = self._place_id_for_image(place.image_sha256)
            if existing is not None:
                raise DuplicatePlaceError(place.image_sha256, existing, self.path)
            if place.leg is not None:
                self._check_leg_start(place.leg)
            place_row = {
                "room_id": self._ensure_room(place.room),
                "x_m": place.x_m,
                "y_m": place.y_m,
                "heading_deg": place.heading_deg,
                "image_sha256": place.image_sha256,
                "image_width_px": width_px,
                "image_height_px": height_px,
                "captured_utc": place.captured_utc,
                "source": place.source,
                "added_utc": utc_now_iso(),
                "camera": camera,
            }
            place_id = _inserted_id(self.db.table("places").insert(place_row))
            self.db.table("fingerprints").insert_all(
                [{**row, "place_id": place_id} for row in rows]
            )
            if place.leg is not None:
                self.db.execute(
                    "INSERT INTO legs (place_id, from_place_id, via_json) VALUES (?, ?, ?)",
                    [place_id, place.leg.from_place, via_to_json(place.leg)],
                )
            self._log_change("place", {"place_id": place_id})
        return place_id

    def _check_leg_start(self, leg: Leg) -> None:
        """``UnknownPlaceError`` if the place ``leg`` comes from does not exist, ``ValueError``
        if it has no position (a leg joins two odometry positions)."""
        row = self.db.execute(
            "SELECT x_m, y_m FROM places WHERE id = ?", [leg.from_place]
        ).fetchone()
        if row is None:
            raise UnknownPlaceError(
                f"the leg starts at place {leg.from_place}, which {self.path} does not have",
                self.path,
            )
        if row[0] is None or row[1] is None:
            raise ValueError(
                f"the leg starts at place {leg.from_place}, which has no position to drive from"
            )

    def _place_id_for_image(self, image_sha256: str) -> int | None:
        row = self.db.execute(
            "SELECT id FROM places WHERE image_sha256 = ?", [image_sha256]
        ).fetchone()
        return None if row is None else int(row[0])

    @_translated
    def places(self, room: str | None = None) -> list[Place]:
        """All places (of ``room`` if given, which must exist), by id."""
        sql = _SELECT_PLACES
        params: list[Any] = []
        if room is not None:
            sql += " WHERE p.room_id = ?"
            params.append(self.room_id(room))
        rows = self.db.execute(sql + " ORDER BY p.id", params).fetchall()
        return [_place_from_row(row) for row in rows]

    @_translated
    def place(self, place_id: int) -> Place:
        """The place with id ``place_id``; raises :class:`UnknownPlaceError` if there is none."""
        row = self.db.execute(_SELECT_PLACES + " WHERE p.id = ?", [place_id]).fetchone()
        if row is None:
            raise UnknownPlaceError(f"unknown place {place_id} in {self.path}", self.path)
        return _place_from_row(row)

    @_translated
    def fingerprint_counts(self) -> dict[str, int]:
        """Number of stored fingerprints per detector."""
        rows = self.db.execute(
            "SELECT detector, COUNT(*) FROM fingerprints GROUP BY detector ORDER BY detector"
        ).fetchall()
        return dict(rows)

    @_translated
    def stored_params(self, detector: str | None = None) -> dict[str, Any] | None:
        """The extraction parameters recorded with the map's first fingerprint (of ``detector``,
        if given; None for a map without one): what a new place or a query must share to be
        comparable."""
        where, args = ("WHERE detector = ?", [detector]) if detector is not None else ("", [])
        row = self.db.execute(
            f"SELECT params_json FROM fingerprints {where} ORDER BY id LIMIT 1", args
        ).fetchone()
        return None if row is None else dict(json.loads(row[0]))

    @_translated
    def file_size_bytes(self) -> int:
        """Size on disk of the database file plus its write-ahead log."""
        wal = self.path.with_name(self.path.name + "-wal")
        return self.path.stat().st_size + (wal.stat().st_size if wal.exists() else 0)

    def info(self) -> MapInfo:
        """Rooms with their place counts, edges, fingerprints per detector and file size."""
        return MapInfo(
            path=self.path,
            schema_version=self.schema_version(),
            file_size_bytes=self.file_size_bytes(),
            rooms=self.rooms(),
            edges=self.edges(),
            fingerprints_per_detector=(counts := self.fingerprint_counts()),
            fingerprints_without_sizes=int(
                self.db.execute(
                    "SELECT COUNT(*) FROM fingerprints WHERE keypoint_sizes_px IS NULL"
                ).fetchone()[0]
            ),
            likelihoods={d: model for d in counts if (model := self.likelihood(d)) is not None},
        )


__all__ = ["SCHEMA_VERSION", "DuplicatePlaceError", "MapDatabase", "utc_now_iso"]


def _inserted_id(table: sqlite_utils.db.Table) -> int:
    """The rowid the last ``insert`` on ``table`` gave (sqlite-utils types it as optional)."""
    if table.last_pk is None:
        raise RuntimeError(f"insert into {table.name} returned no row id")
    return int(table.last_pk)


def _likelihood_key(detector: str) -> str:
    """The ``meta`` key of a detector's likelihood calibration."""
    return f"likelihood:{detector}"
