"""Errors of the map database: one hierarchy, each message names the file, room or column.

Every failure a user can cause (a wrong path, a file that is not a map, a newer schema, a locked,
read-only or full database, an unknown room, a bad manifest) raises a subclass of
:class:`MapDatabaseError`, so a command line catches one type and prints its message.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

# Primary SQLite result codes (the low byte of an extended code), https://sqlite.org/rescode.html
SQLITE_BUSY = 5
SQLITE_LOCKED = 6
SQLITE_READONLY = 8
SQLITE_IOERR = 10
SQLITE_CORRUPT = 11
SQLITE_FULL = 13
SQLITE_CANTOPEN = 14
SQLITE_NOTADB = 26


class MapDatabaseError(Exception):
    """Base of every error raised by :mod:`mapdb`; ``path`` is the database (or input) file."""

    def __init__(self, message: str, path: Path | str | None = None) -> None:
        super().__init__(message)
        self.path = Path(path) if path is not None else None


class MapFileNotFoundError(MapDatabaseError):
    """The database file does not exist and the operation does not create one."""


class NotAMapDatabaseError(MapDatabaseError):
    """The file is not SQLite, is corrupt, or is SQLite but not a toploc map."""


class SchemaVersionError(MapDatabaseError):
    """The database has a schema version this code cannot use (newer, or unmigrated read-only)."""


class ReadOnlyDatabaseError(MapDatabaseError):
    """A write was attempted on a database opened read-only or stored read-only."""


class DatabaseLockedError(MapDatabaseError):
    """Another connection holds the write lock longer than the busy timeout."""


class DiskFullError(MapDatabaseError):
    """The disk (or the database's page limit) is full; the transaction was rolled back."""


class UnknownRoomError(MapDatabaseError):
    """A room name that is not in the map."""

    def __init__(self, room: str, path: Path | str | None = None) -> None:
        where = f" in {path}" if path is not None else ""
        super().__init__(f"unknown room {room!r}{where}", path)
        self.room = room


class DuplicatePlaceError(MapDatabaseError):
    """The image (same SHA-256) is already a place of the map; ``place_id`` is that place."""

    def __init__(self, image_sha256: str, place_id: int, path: Path | str) -> None:
        super().__init__(f"image {image_sha256[:12]}… is already place {place_id} of {path}", path)
        self.place_id = place_id


class UnknownPlaceError(MapDatabaseError):
    """A place id that is not in the map."""


class BuildAbortedError(MapDatabaseError):
    """A build stopped early (a feature-extraction worker died); committed places are complete."""


class InvalidValueError(MapDatabaseError, ValueError):
    """A value the map refuses to store (a blank, too long or control-character name; a NaN or
    infinite coordinate); a ``ValueError`` too."""


class EmptyMapError(MapDatabaseError, ValueError):
    """A map with nothing to localize against (no place, or none with the detector's
    fingerprints); a ``ValueError`` too, as callers caught before."""


class ReplicaError(MapDatabaseError, ValueError):
    """A replica that cannot take a snapshot or changes as they are (another map's, ahead of
    the map, out of order, data that does not decode); the replica was left as it was."""


class UnknownVersionError(MapDatabaseError, ValueError):
    """Changes asked for after a version the map does not have (ahead of it, or negative)."""


class ManifestError(MapDatabaseError):
    """A dataset manifest that is missing, lacks a column, or has a malformed value."""


def translate_sqlite_error(error: sqlite3.Error, path: Path | str) -> MapDatabaseError:
    """Map a ``sqlite3`` exception to the :class:`MapDatabaseError` subclass that explains it.

    ``path`` is the database file, named in every message. Unknown codes become the base class
    with SQLite's own message, still naming the file.
    """
    code = (getattr(error, "sqlite_errorcode", None) or 0) & 0xFF
    text = str(error)
    if code in (SQLITE_NOTADB, SQLITE_CORRUPT):
        return NotAMapDatabaseError(f"{path} is not a valid SQLite database ({text})", path)
    if code == SQLITE_READONLY:
        return ReadOnlyDatabaseError(f"{path} is read-only, cannot write to it ({text})", path)
    if code in (SQLITE_BUSY, SQLITE_LOCKED):
        return DatabaseLockedError(
            f"{path} is locked by another process or connection; try again later ({text})", path
        )
    if code == SQLITE_FULL:
        return DiskFullError(
            f"no space left for {path}: the disk or the database size limit is full; "
            f"nothing was written by the failed operation ({text})",
            path,
        )
    if code == SQLITE_CANTOPEN:
        return MapDatabaseError(f"cannot open {path} ({text})", path)
    if code == SQLITE_IOERR:
        return MapDatabaseError(f"I/O error on {path} ({text})", path)
    return MapDatabaseError(f"database error on {path}: {text}", path)
