"""The schema of the map database and its numbered migrations.

``MIGRATIONS[i]`` brings a database from schema version ``i`` to ``i + 1``; version 0 is an empty
file. The version lives in ``meta(key='schema_version')``. Each migration runs in its own
``BEGIN IMMEDIATE`` transaction together with the version bump, so an interrupted migration
leaves the previous version intact. To change the schema, append a function; never edit one that
has shipped.

Tables (all STRICT; positions in metres and headings in degrees in the frame of the place's room):

- ``meta(key TEXT PK, value TEXT)``
- ``rooms(id, name UNIQUE, created_utc)``
- ``edges(room_a_id, room_b_id, created_utc)``: undirected, stored once with
  ``room_a_id < room_b_id``; both reference ``rooms``.
- ``places(id, room_id -> rooms, x_m, y_m, heading_deg (NULL = unknown), image_sha256 UNIQUE,
  image_width_px, image_height_px, captured_utc, source, added_utc, camera)``; ``camera`` is the
  panorama's model, ``cylinder`` or ``equirect`` (version 2; older places are cylinders), and the
  image size is that of the panorama the features were extracted on.
- ``fingerprints(id, place_id -> places, detector, n_keypoints, descriptor_dim, keypoints_xy,
  bearings_rad, descriptor_dtype, descriptors (blobs, see :mod:`mapdb.codec`), alv_x, alv_y,
  params_json)``, UNIQUE ``(place_id, detector)``, indexed by ``(detector, place_id)`` so one
  detector's rows come in place order without sorting the blobs.
- ``changes(version PK, kind, ref_json, created_utc)`` (version 3): the map's change log. Each
  write (a place with its fingerprints, a room, an edge, a likelihood) takes the next version
  in its own transaction; ``ref_json`` names what it wrote (a place id, a room id, an edge's
  room ids, a detector), whose rows are read from the tables when a replica asks for the change
  (:mod:`mapdb.replica`). ``meta`` holds ``map_version`` (the last version; 0: the map as it was
  before version 3, or empty) and ``map_id`` (the map's own id, a random one when it was
  migrated: what replicas of it check; :meth:`mapdb.database.MapDatabase.map_id`).
- ``legs(place_id PK -> places, from_place_id -> places, via_json)`` (version 4): the drive a
  place was recorded on (:class:`mapdb.records.Leg`): the place recorded before it on that
  drive and the odometry positions between them (JSON ``[[x_m, y_m], ...]``); both places'
  poses are then in that drive's odometry frame. Written with its place, in its change.
- ``fingerprints.keypoint_sizes_px`` (version 5): the keypoints' diameters (a blob, see
  :mod:`mapdb.codec`), which homing uses to tell nearer from farther; NULL for the places
  stored before (their images are not kept, so they cannot be found again).
"""

from __future__ import annotations

import secrets
from collections.abc import Callable, Sequence

import sqlite_utils

Migration = Callable[[sqlite_utils.Database], None]

META_TABLE = "meta"
VERSION_KEY = "schema_version"
MAP_VERSION_KEY = "map_version"
MAP_ID_KEY = "map_id"
CHANGES_TABLE = "changes"


def new_map_id() -> str:
    """A fresh map id: ``map-`` and 12 random hex digits (one key chunk)."""
    return f"map-{secrets.token_hex(6)}"


def _v1_initial(db: sqlite_utils.Database) -> None:
    """Version 1: rooms, edges, places, fingerprints."""
    db.create_table(
        "rooms",
        {"id": int, "name": str, "created_utc": str},
        pk="id",
        not_null={"name", "created_utc"},
        strict=True,
    )
    db.table("rooms").create_index(["name"], unique=True)
    db.create_table(
        "edges",
        {"room_a_id": int, "room_b_id": int, "created_utc": str},
        pk=("room_a_id", "room_b_id"),
        foreign_keys=[("room_a_id", "rooms", "id"), ("room_b_id", "rooms", "id")],
        not_null={"room_a_id", "room_b_id", "created_utc"},
        strict=True,
    )
    db.table("edges").create_index(["room_b_id"])
    db.create_table(
        "places",
        {
            "id": int,
            "room_id": int,
            "x_m": float,
            "y_m": float,
            "heading_deg": float,
            "image_sha256": str,
            "image_width_px": int,
            "image_height_px": int,
            "captured_utc": str,
            "source": str,
            "added_utc": str,
        },
        pk="id",
        foreign_keys=[("room_id", "rooms", "id")],
        not_null={
            "room_id",
            "image_sha256",
            "image_width_px",
            "image_height_px",
            "source",
            "added_utc",
        },
        strict=True,
    )
    db.table("places").create_index(["image_sha256"], unique=True)
    db.table("places").create_index(["room_id"])
    db.create_table(
        "fingerprints",
        {
            "id": int,
            "place_id": int,
            "detector": str,
            "n_keypoints": int,
            "descriptor_dim": int,
            "keypoints_xy": bytes,
            "bearings_rad": bytes,
            "descriptor_dtype": str,
            "descriptors": bytes,
            "alv_x": float,
            "alv_y": float,
            "params_json": str,
        },
        pk="id",
        foreign_keys=[("place_id", "places", "id")],
        not_null={
            "place_id",
            "detector",
            "n_keypoints",
            "descriptor_dim",
            "keypoints_xy",
            "bearings_rad",
            "descriptor_dtype",
            "descriptors",
            "alv_x",
            "alv_y",
            "params_json",
        },
        strict=True,
    )
    db.table("fingerprints").create_index(["place_id", "detector"], unique=True)
    db.table("fingerprints").create_index(["detector", "place_id"])


def _v2_camera(db: sqlite_utils.Database) -> None:
    """Version 2: each place records its camera model (maps made before were all cylinders)."""
    db.execute("ALTER TABLE places ADD COLUMN camera TEXT NOT NULL DEFAULT 'cylinder'")


def _v3_versions(db: sqlite_utils.Database) -> None:
    """Version 3: the change log, the map's version (0: what it held before) and its own id."""
    db.create_table(
        CHANGES_TABLE,
        {"version": int, "kind": str, "ref_json": str, "created_utc": str},
        pk="version",
        not_null={"kind", "ref_json", "created_utc"},
        strict=True,
    )
    db.execute(
        f"INSERT OR IGNORE INTO {META_TABLE} (key, value) VALUES (?, '0'), (?, ?)",
        [MAP_VERSION_KEY, MAP_ID_KEY, new_map_id()],
    )


def _v4_legs(db: sqlite_utils.Database) -> None:
    """Version 4: the drive each place was recorded on, where known (places before: none)."""
    db.create_table(
        "legs",
        {"place_id": int, "from_place_id": int, "via_json": str},
        pk="place_id",
        foreign_keys=[("place_id", "places", "id"), ("from_place_id", "places", "id")],
        not_null={"place_id", "from_place_id", "via_json"},
        strict=True,
    )
    db.table("legs").create_index(["from_place_id"])


def _v5_keypoint_sizes(db: sqlite_utils.Database) -> None:
    """Version 5: each fingerprint's keypoint sizes (NULL for those stored before)."""
    db.execute("ALTER TABLE fingerprints ADD COLUMN keypoint_sizes_px BLOB")


MIGRATIONS: tuple[Migration, ...] = (
    _v1_initial,
    _v2_camera,
    _v3_versions,
    _v4_legs,
    _v5_keypoint_sizes,
)
SCHEMA_VERSION = len(MIGRATIONS)

READ_ONLY_VIEWS: dict[Migration, str] = {
    _v2_camera: "CREATE TEMP VIEW places AS SELECT *, 'cylinder' AS camera FROM main.places",
    _v3_versions: (
        f"CREATE TEMP VIEW {CHANGES_TABLE} AS SELECT 0 AS version, '' AS kind, '' AS ref_json, "
        "'' AS created_utc WHERE 0"
    ),
    _v4_legs: (
        "CREATE TEMP VIEW legs AS SELECT 0 AS place_id, 0 AS from_place_id, '' AS via_json WHERE 0"
    ),
    _v5_keypoint_sizes: (
        "CREATE TEMP VIEW fingerprints AS SELECT *, NULL AS keypoint_sizes_px "
        "FROM main.fingerprints"
    ),
}
"""For a migration, the SQL that shows its result to a read-only connection without writing:
a ``TEMP`` view (kept in memory) named like the table it shadows. A map too old to have one
for every missing migration must be opened for writing once, which migrates it."""


def read_schema_version(db: sqlite_utils.Database) -> int | None:
    """The schema version of ``db``: 0 for an empty file, ``None`` if it is not a toploc map.

    "Not a map" means other tables exist but no ``meta`` table, or ``meta`` lacks a valid
    version (missing, NULL, not a whole number, or negative). Reads only; raises
    ``sqlite3.DatabaseError`` if the file is not SQLite.
    """
    names = db.table_names()
    if META_TABLE not in names:
        return 0 if not names else None
    rows = list(db.query(f"SELECT value FROM {META_TABLE} WHERE key = ?", [VERSION_KEY]))
    if not rows:
        return None
    try:
        version = int(rows[0]["value"])
    except (TypeError, ValueError):  # NULL, a blob or text that is not a number
        return None
    return version if version >= 0 else None


def migrate(db: sqlite_utils.Database, migrations: Sequence[Migration] = MIGRATIONS) -> int:
    """Apply the migrations ``db`` lacks, each in its own transaction; return the new version.

    The caller has checked that the current version is not newer than ``len(migrations)``.
    """
    version = read_schema_version(db) or 0
    for number in range(version + 1, len(migrations) + 1):
        db.execute("BEGIN IMMEDIATE")
        try:
            if number == 1:
                db.create_table(
                    META_TABLE, {"key": str, "value": str}, pk="key", strict=True, ignore=True
                )
            migrations[number - 1](db)
            db.execute(
                f"INSERT OR REPLACE INTO {META_TABLE} (key, value) VALUES (?, ?)",
                [VERSION_KEY, str(number)],
            )
            db.execute("COMMIT")
        except BaseException:
            if db.conn.in_transaction:
                db.execute("ROLLBACK")
            raise
        version = number
    return version
