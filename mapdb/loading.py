"""Fast bulk reads of fingerprints: every fingerprint of a map in one query.

Two shapes for the localizer's start-up:

- :func:`load_fingerprints`: one :class:`StoredFingerprint` per (place, detector); keypoints and
  bearings are zero-copy ``np.frombuffer`` views of the blobs, descriptors one cast each.
- :func:`load_fingerprint_table`: one detector stacked into contiguous arrays (all descriptors
  in one ``(N, d)`` matrix, with per-place offsets), built from one ``b"".join`` per column;
  ready for a single nearest-neighbour index over the whole map.
- :func:`load_snapshot`: that table with the places, rooms and room graph, read once at a
  localizer's start-up; for a big map (``on_disk_from`` places or more) a
  :class:`mapdb.store.SqlitePlaceStore` instead, which keeps only the places' metadata and
  reads fingerprints on demand.
"""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np

from mapdb.codec import (
    BEARINGS_DTYPE,
    DESCRIPTOR_STORAGE,
    DESCRIPTORS_DTYPE,
    KEYPOINTS_DTYPE,
    SIZES_DTYPE,
    ParamsCache,
    decode_descriptors,
    fingerprint_from_row,
)
from mapdb.database import MapDatabase
from mapdb.errors import EmptyMapError, translate_sqlite_error
from mapdb.records import (
    FingerprintTable,
    MapSnapshot,
    PlaceStore,
    StoredFingerprint,
    stacked_sizes_px,
)
from mapdb.store import PlaceCatalog, SqlitePlaceStore

_SELECT = (
    "SELECT f.place_id, r.name, f.detector, p.image_width_px, p.image_height_px, "
    "f.n_keypoints, f.descriptor_dim, f.keypoints_xy, f.bearings_rad, f.descriptor_dtype, "
    "f.descriptors, f.alv_x, f.alv_y, f.params_json, f.keypoint_sizes_px "
    "FROM fingerprints f JOIN places p ON p.id = f.place_id JOIN rooms r ON r.id = p.room_id"
)


def _query(map_db: MapDatabase, detector: str | None) -> list[tuple]:
    sql = _SELECT + (" WHERE f.detector = ?" if detector is not None else "")
    params = [detector] if detector is not None else []
    try:
        return map_db.db.execute(sql + " ORDER BY f.place_id, f.detector", params).fetchall()
    except sqlite3.Error as error:
        raise translate_sqlite_error(error, map_db.path) from error


def _stack_descriptors(
    codes: tuple[str, ...], blobs: tuple[bytes, ...], counts: tuple[int, ...], dim: int, total: int
) -> np.ndarray:
    """``(total, dim)`` float32 from per-row blobs: one join and one cast if all share a code."""
    if len(set(codes)) <= 1:
        storage = DESCRIPTOR_STORAGE[codes[0] if codes else "f4"]
        stacked = np.frombuffer(b"".join(blobs), storage).reshape(total, dim)
        return stacked if storage == DESCRIPTORS_DTYPE else stacked.astype(DESCRIPTORS_DTYPE)
    parts = [decode_descriptors(b, c, n, dim) for c, b, n in zip(codes, blobs, counts, strict=True)]
    return np.concatenate(parts).reshape(total, dim)


def load_fingerprints(map_db: MapDatabase, detector: str | None = None) -> list[StoredFingerprint]:
    """Every fingerprint (of ``detector`` if given), ordered by place id then detector."""
    params_of = ParamsCache()
    return [
        StoredFingerprint(
            place_id=row[0],
            room=row[1],
            alv_xy=(row[11], row[12]),
            fingerprint=fingerprint_from_row(
                row[2],
                row[3],
                row[4],
                row[5],
                row[6],
                row[7],
                row[8],
                row[9],
                row[10],
                params_of(row[13]),
                row[14],
            ),
        )
        for row in _query(map_db, detector)
    ]


def load_fingerprint_table(map_db: MapDatabase, detector: str) -> FingerprintTable:
    """All fingerprints of ``detector`` stacked into contiguous arrays (see the class).

    An empty table (no places) has ``descriptor_dim`` 0. Raises ``ValueError`` if stored
    descriptors have differing dimensions.
    """
    rows = _query(map_db, detector)
    params_of = ParamsCache()
    if not rows:
        columns: list[tuple] = [()] * 15
    else:
        columns = list(zip(*rows, strict=True))
    dims = set(columns[6])
    if len(dims) > 1:
        raise ValueError(f"detector {detector!r} has descriptors of several sizes: {dims}")
    dim = dims.pop() if dims else 0
    counts = np.array(columns[5], dtype=np.int64)
    offsets = np.zeros(len(rows) + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    total = int(offsets[-1])
    return FingerprintTable(
        detector=detector,
        place_ids=np.array(columns[0], dtype=np.int64),
        rooms=tuple(columns[1]),
        offsets=offsets,
        keypoints_xy=np.frombuffer(b"".join(columns[7]), KEYPOINTS_DTYPE).reshape(total, 2),
        bearings_rad=np.frombuffer(b"".join(columns[8]), BEARINGS_DTYPE),
        descriptors=_stack_descriptors(columns[9], columns[10], columns[5], dim, total),
        alv_xy=np.array([columns[11], columns[12]], dtype=np.float64).T.reshape(len(rows), 2),
        image_sizes_px=np.array([columns[3], columns[4]], dtype=np.int64).T.reshape(len(rows), 2),
        params=tuple(params_of(text) for text in columns[13]),
        keypoint_sizes_px=stacked_sizes_px(
            [None if b is None else np.frombuffer(b, SIZES_DTYPE) for b in columns[14]],
            columns[5],
        ),
    )


def open_for_reading(path: Path) -> MapDatabase:
    """The map at ``path`` opened read-only, never written: on read-only media too, and a map
    made by an older toploc is read through views of the current schema (see
    :meth:`MapDatabase.open`)."""
    return MapDatabase.open(path, create=False, readonly=True)


def load_snapshot(
    path: Path | str, detector: str = "sift", on_disk_from: int | None = None
) -> MapSnapshot:
    """Read what a localizer needs from the map at ``path`` (read-only, then closed): the
    fingerprints stacked in memory, or, if the map has ``on_disk_from`` or more ``detector``
    places, a :class:`~mapdb.store.SqlitePlaceStore` over them (metadata only in memory).

    Raises :class:`mapdb.errors.EmptyMapError` (a ``ValueError``) if the map has no place with
    a ``detector`` fingerprint; every error is a :class:`mapdb.errors.MapDatabaseError`.
    """
    path = Path(path)
    table: PlaceStore
    with open_for_reading(path) as opened, opened.reading() as map_db:
        on_disk = on_disk_from is not None and _count(map_db, detector) >= on_disk_from
        if on_disk:
            table = SqlitePlaceStore(path, PlaceCatalog.read(map_db, detector))
        else:
            table = load_fingerprint_table(map_db, detector)
        places = map_db.places()
        rooms = tuple(room.name for room in map_db.rooms())
        edges = tuple(map_db.edges())
        likelihood = map_db.likelihood(detector)
    if not len(table.place_ids):
        what = "no places" if not places else f"no place with a {detector!r} fingerprint"
        raise EmptyMapError(f"map {path} has {what}: build it first (toploc map build)", path)
    with_fingerprint = {int(p) for p in table.place_ids}
    kept = tuple(p for p in places if p.id in with_fingerprint)
    kept_rooms = tuple(r for r in rooms if any(p.room == r for p in kept))
    return MapSnapshot(path, table, kept, kept_rooms, edges, likelihood)


def _count(map_db: MapDatabase, detector: str) -> int:
    sql = "SELECT COUNT(*) FROM fingerprints WHERE detector = ?"
    try:
        return int(map_db.db.execute(sql, [detector]).fetchone()[0])
    except sqlite3.Error as error:
        raise translate_sqlite_error(error, map_db.path) from error
