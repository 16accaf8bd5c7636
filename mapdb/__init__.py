"""The SQLite map: rooms, room graph, places and fingerprints.

The map is topological: each room has its own metric frame; a place's ``x_m``, ``y_m`` and
``heading_deg`` are in the frame of its room. Entry points:

- :class:`MapDatabase` (``MapDatabase.open(path)``): rooms, edges, places, ``add_place``.
- :func:`load_fingerprints` / :func:`load_fingerprint_table`: every fingerprint in one query.
- :func:`room_graph` / :func:`export_graphml`: the room graph as networkx / GraphML.
- :func:`read_manifest` + :func:`build_map`: import a dataset folder with an injected extractor.
- :class:`MapDatabaseError` and its subclasses: every failure, naming the file, room or column.
"""

from mapdb.build import BuildReport, Outcome, Status, build_map
from mapdb.database import MapDatabase
from mapdb.dataset import ManifestEntry, read_manifest, sha256_file
from mapdb.errors import (
    BuildAbortedError,
    DatabaseLockedError,
    DiskFullError,
    DuplicatePlaceError,
    ManifestError,
    MapDatabaseError,
    MapFileNotFoundError,
    NotAMapDatabaseError,
    ReadOnlyDatabaseError,
    SchemaVersionError,
    UnknownPlaceError,
    UnknownRoomError,
)
from mapdb.graph import export_graphml, room_graph
from mapdb.loading import (
    FingerprintTable,
    StoredFingerprint,
    load_fingerprint_table,
    load_fingerprints,
)
from mapdb.records import MapInfo, NewPlace, Place, RoomSummary
from mapdb.schema import SCHEMA_VERSION

__all__ = [
    "SCHEMA_VERSION",
    "BuildAbortedError",
    "BuildReport",
    "DatabaseLockedError",
    "DiskFullError",
    "DuplicatePlaceError",
    "FingerprintTable",
    "ManifestEntry",
    "ManifestError",
    "MapDatabase",
    "MapDatabaseError",
    "MapFileNotFoundError",
    "MapInfo",
    "NewPlace",
    "NotAMapDatabaseError",
    "Outcome",
    "Place",
    "ReadOnlyDatabaseError",
    "RoomSummary",
    "SchemaVersionError",
    "Status",
    "StoredFingerprint",
    "UnknownPlaceError",
    "UnknownRoomError",
    "build_map",
    "export_graphml",
    "load_fingerprint_table",
    "load_fingerprints",
    "read_manifest",
    "room_graph",
    "sha256_file",
]
