"""A map's fingerprints read from its SQLite file on demand, for maps too big to hold in memory.

:class:`SqlitePlaceStore` is the on-disk :class:`mapdb.records.PlaceStore`: it keeps only the
compact per-place metadata (:class:`PlaceCatalog`: ids, rooms, keypoint counts, ALVs, image
sizes, extraction parameters; a few hundred bytes a place) and reads the full fingerprints of
the places a localizer asks for (the shortlist, a calibration query, a homing goal) in one
query each time, keeping the last ``cache_places`` of them. Each read opens the map read-only
for the duration of the query, so the store holds no database handle between reads.

A fingerprint is read by its row id as the catalogue saw it: a fingerprint replaced or removed
since (the map changed under a loaded store) is a one-line error naming the place, as is a blob
that does not decode. :meth:`SqlitePlaceStore.descriptor_batches` streams the descriptors place
by place in batches (an index is built without holding them all at once).
"""

from __future__ import annotations

import hashlib
import sqlite3
import threading
from collections import OrderedDict
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from homing.cameras import CameraModel, ParamValue, camera_from_params
from mapdb.codec import ParamsCache, decode_descriptors, fingerprint_from_row
from mapdb.database import MapDatabase
from mapdb.errors import MapDatabaseError, translate_sqlite_error
from mapdb.records import Fingerprint

CACHE_PLACES = 32
"""Full fingerprints a store keeps (the last read; 32 x 1,000 SIFT keypoints is about 17 MB)."""

_CATALOG = (
    "SELECT f.id, f.place_id, r.name, p.image_width_px, p.image_height_px, f.n_keypoints, "
    "f.descriptor_dim, f.alv_x, f.alv_y, f.params_json, p.image_sha256 "
    "FROM fingerprints f JOIN places p ON p.id = f.place_id JOIN rooms r ON r.id = p.room_id "
    "WHERE f.detector = ? ORDER BY f.place_id"
)
_FULL = (
    "SELECT f.id, f.n_keypoints, f.descriptor_dim, f.keypoints_xy, f.bearings_rad, "
    "f.descriptor_dtype, f.descriptors, f.keypoint_sizes_px FROM fingerprints f "
    "WHERE f.id IN ({})"
)
_DESCRIPTORS = (
    "SELECT f.id, f.n_keypoints, f.descriptor_dim, f.descriptor_dtype, f.descriptors "
    "FROM fingerprints f WHERE f.id IN ({})"
)


@dataclass(frozen=True)
class PlaceCatalog:
    """The compact metadata of one detector's places, place ``i`` of each field, by place id.

    ``fingerprint_ids`` (m,) the fingerprints' row ids; ``image_keys`` (m,) int64 a 64-bit
    digest of each place's image SHA-256 (with the ids, what identifies the places an index was
    built over); ``keypoint_counts`` (m,) int64; ``alv_xy`` (m, 2); ``image_sizes_px``
    (m, 2) ``(width, height)``; ``params`` each place's extraction parameters (shared).
    """

    detector: str
    place_ids: np.ndarray
    fingerprint_ids: np.ndarray
    image_keys: np.ndarray
    rooms: tuple[str, ...]
    keypoint_counts: np.ndarray
    descriptor_dim: int
    alv_xy: np.ndarray
    image_sizes_px: np.ndarray
    params: tuple[Mapping[str, ParamValue], ...]

    @classmethod
    def read(cls, map_db: MapDatabase, detector: str) -> PlaceCatalog:
        """The catalogue of ``detector``'s places in ``map_db`` (no blob is read). Raises
        ``ValueError`` if stored descriptors have differing dimensions."""
        try:
            rows = map_db.db.execute(_CATALOG, [detector]).fetchall()
        except sqlite3.Error as error:
            raise translate_sqlite_error(error, map_db.path) from error
        columns: list[tuple] = list(zip(*rows, strict=True)) if rows else [()] * 11
        dims = set(columns[6])
        if len(dims) > 1:
            raise ValueError(f"detector {detector!r} has descriptors of several sizes: {dims}")
        params_of = ParamsCache()
        rooms: dict[str, str] = {}
        return cls(
            detector=detector,
            place_ids=np.array(columns[1], dtype=np.int64),
            fingerprint_ids=np.array(columns[0], dtype=np.int64),
            image_keys=np.array([_image_key(h) for h in columns[10]], dtype=np.int64),
            rooms=tuple(rooms.setdefault(name, name) for name in columns[2]),
            keypoint_counts=np.array(columns[5], dtype=np.int64),
            descriptor_dim=dims.pop() if dims else 0,
            alv_xy=np.array([columns[7], columns[8]], dtype=np.float64).T.reshape(len(rows), 2),
            image_sizes_px=np.array([columns[3], columns[4]], dtype=np.int64).T.reshape(-1, 2),
            params=tuple(params_of(text) for text in columns[9]),
        )


def _image_key(image_sha256: str) -> int:
    digest = hashlib.blake2b(image_sha256.encode(), digest_size=8).digest()
    return int.from_bytes(digest, "little", signed=True)


class SqlitePlaceStore:
    """One detector's places of the map at ``path``: :class:`PlaceCatalog` in memory, full
    fingerprints read on demand (see the module). Safe to read from several threads."""

    def __init__(self, path: Path, catalog: PlaceCatalog, cache_places: int = CACHE_PLACES) -> None:
        if cache_places < 0:
            raise ValueError(f"cache_places must be >= 0, got {cache_places}")
        self.path = Path(path)
        self.catalog = catalog
        self.cache_places = cache_places
        self._cache: OrderedDict[int, Fingerprint] = OrderedDict()
        self._lock = threading.Lock()
        self.reads = 0  # fingerprints read from the file so far

    @classmethod
    def open(
        cls, path: Path | str, detector: str, cache_places: int = CACHE_PLACES
    ) -> SqlitePlaceStore:
        """The store of ``detector``'s places of the map at ``path`` (read-only)."""
        with MapDatabase.open(path, create=False, readonly=True) as map_db:
            return cls(Path(path), PlaceCatalog.read(map_db, detector), cache_places)

    @property
    def detector(self) -> str:
        return self.catalog.detector

    @property
    def place_ids(self) -> np.ndarray:
        return self.catalog.place_ids

    @property
    def rooms(self) -> tuple[str, ...]:
        return self.catalog.rooms

    @property
    def alv_xy(self) -> np.ndarray:
        return self.catalog.alv_xy

    @property
    def image_sizes_px(self) -> np.ndarray:
        return self.catalog.image_sizes_px

    @property
    def params(self) -> tuple[Mapping[str, ParamValue], ...]:
        return self.catalog.params

    @property
    def keypoint_counts(self) -> np.ndarray:
        return self.catalog.keypoint_counts

    @property
    def descriptor_dim(self) -> int:
        return self.catalog.descriptor_dim

    @cached_property
    def cameras(self) -> tuple[CameraModel, ...]:
        """Each place's camera model (built once; places of one camera share it)."""
        made: dict[tuple[int, int, int], CameraModel] = {}
        return tuple(
            made.setdefault((int(w), int(h), id(p)), camera_from_params(int(w), int(h), p))
            for (w, h), p in zip(self.image_sizes_px, self.params, strict=True)
        )

    def fingerprint(self, i: int) -> Fingerprint:
        """The full fingerprint of the place at index ``i``."""
        return self.fingerprints([i])[0]

    def fingerprints(self, indices: Sequence[int] | np.ndarray) -> list[Fingerprint]:
        """The full fingerprints of the places at ``indices`` (in that order), those not kept
        read in one query. :class:`MapDatabaseError` naming the place if its fingerprint is
        gone or changed since the catalogue was read, or does not decode."""
        wanted = [int(i) for i in indices]
        for i in wanted:
            if not 0 <= i < len(self.place_ids):
                raise IndexError(f"place index {i} is not in the map {self.path}")
        with self._lock:
            found = {i: self._cache[i] for i in wanted if i in self._cache}
            for i in found:
                self._cache.move_to_end(i)
        missing = sorted(set(wanted) - set(found))
        if missing:
            found |= self._read(missing)
            with self._lock:
                for i in missing:
                    self._cache[i] = found[i]
                    self._cache.move_to_end(i)
                while len(self._cache) > self.cache_places:
                    self._cache.popitem(last=False)
        return [found[i] for i in wanted]

    def _read(self, indices: list[int]) -> dict[int, Fingerprint]:
        by_row = {int(self.catalog.fingerprint_ids[i]): i for i in indices}
        rows = self._select(_FULL, list(by_row))
        result = {}
        for row_id, n, dim, keypoints, bearings, code, blob, sizes in rows:
            i = by_row[row_id]
            try:
                width, height = (int(v) for v in self.image_sizes_px[i])
                fp = fingerprint_from_row(
                    self.detector, width, height, n, dim, keypoints, bearings, code, blob,
                    self.params[i], sizes,
                )  # fmt: skip
            except (ValueError, KeyError) as error:
                raise self._undecodable(i, error) from None
            result[i] = fp
        self.reads += len(result)
        for i in indices:
            if i not in result:
                raise MapDatabaseError(
                    f"map {self.path}: the {self.detector} fingerprint of place "
                    f"{int(self.place_ids[i])} is gone or was replaced since the map was loaded; "
                    "load the map again",
                    self.path,
                )
        return result

    def _undecodable(self, i: int, error: Exception) -> MapDatabaseError:
        return MapDatabaseError(
            f"map {self.path}: the {self.detector} fingerprint of place "
            f"{int(self.place_ids[i])} does not decode ({error})",
            self.path,
        )

    def _select(self, sql: str, row_ids: list[int]) -> list[tuple]:
        query = sql.format(",".join("?" * len(row_ids)))
        with MapDatabase.open(self.path, create=False, readonly=True) as map_db:
            try:
                return map_db.db.execute(query, row_ids).fetchall()
            except sqlite3.Error as error:
                raise translate_sqlite_error(error, self.path) from error

    def descriptor_batches(
        self, start: int = 0, batch_places: int = 256
    ) -> Iterator[list[np.ndarray]]:
        """The descriptors (n, d) float32 of the places from index ``start`` on, in place
        order, ``batch_places`` places per batch (one query each; nothing kept)."""
        for first in range(start, len(self.place_ids), batch_places):
            indices = list(range(first, min(first + batch_places, len(self.place_ids))))
            by_row = {int(self.catalog.fingerprint_ids[i]): i for i in indices}
            got: dict[int, np.ndarray] = {}
            for row_id, n, dim, code, blob in self._select(_DESCRIPTORS, list(by_row)):
                try:
                    got[by_row[row_id]] = decode_descriptors(blob, code, n, dim)
                except (ValueError, KeyError) as error:
                    raise self._undecodable(by_row[row_id], error) from None
            if len(got) < len(indices):
                gone = next(i for i in indices if i not in got)
                raise MapDatabaseError(
                    f"map {self.path}: the {self.detector} fingerprint of place "
                    f"{int(self.place_ids[gone])} is gone or was replaced since the map was "
                    "loaded; load the map again",
                    self.path,
                )
            yield [got[i] for i in indices]

    def sample_descriptors(self, n: int, seed: int = 0, batch_places: int = 256) -> np.ndarray:
        """About ``n`` descriptors (k, d) float32 spread over every place (the same share of
        each place's keypoints, seeded), streamed; for training an index."""
        total = int(self.keypoint_counts.sum())
        share = min(1.0, n / total) if total else 0.0
        rng = np.random.default_rng(seed)
        parts = []
        for batch in self.descriptor_batches(0, batch_places):
            for descriptors in batch:
                keep = rng.random(len(descriptors)) < share
                parts.append(descriptors[keep])
        dim = self.descriptor_dim
        return np.concatenate(parts) if parts else np.zeros((0, dim), dtype=np.float32)
