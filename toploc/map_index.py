"""The compact retrieval index of a big map, kept in a file beside the map and extended as the
map grows.

A map read from disk (:class:`mapdb.store.SqlitePlaceStore`) is shortlisted by a
:class:`localizer.retrieval.CompactPlaceIndex`. Training its quantisers and encoding every
descriptor takes minutes at 10,000 places, so the index is kept in ``<map>.<detector>-index.npz``
beside the map with the places it was built over: each place's id, fingerprint row id and the
a digest of its image hash (what the map already has; no schema change). On load:

- the file's places are the map's first places, in order: the index is read, and the places
  added since (``map add``, the map node's ``map/add``, then the service's refresh) are encoded
  with the trained quantisers and added, streamed from the map: no retraining, no rebuild;
- otherwise (a place removed or re-extracted, another map's file) it is stale, and a damaged
  file is unreadable: both are said in one log line naming the file, and the index is built
  again (trained on a sample streamed from the map, then every place encoded in batches), so
  no data is lost: the map is the truth, the file a cache;
- the map has outgrown the index's lists (:data:`REBUILD_GROWTH`): built again too.

The file is written whole (a temporary file renamed over it); where it cannot be written (a
read-only folder) the index is used in memory and the failure logged.
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from localizer.retrieval import CompactParams, CompactPlaceIndex, lists_for, training_size
from mapdb.store import SqlitePlaceStore

_log = logging.getLogger(__name__)

FORMAT = 2
"""The cache file's layout version (a file of another is stale): 1 held 8-bit PQ codes
(``PQ16x8``), 2 fast-scan 4-bit ones (``PQ32x4fs``, :class:`~localizer.retrieval.CompactParams`)."""

REBUILD_GROWTH = 4
"""Rebuild when :func:`~localizer.retrieval.lists_for` the grown map is this many times the
index's lists (its lists would hold 16 times the codes they were sized for)."""

BATCH_PLACES = 64
"""Places read and encoded per batch while building or extending (64 x 1,000 SIFT keypoints:
about 33 MB of float32 at once)."""


def index_path(db_path: Path, detector: str) -> Path:
    """The index cache file of ``detector``'s places of the map at ``db_path``."""
    return db_path.with_name(f"{db_path.name}.{detector}-index.npz")


@dataclass(frozen=True)
class IndexReport:
    """What :func:`compact_index` did: ``"read"``, ``"extended"`` (``added`` places encoded)
    or ``"built"`` (``why``: no file, stale, damaged or outgrown), and how long it took (s)."""

    action: str
    added: int
    why: str
    seconds: float


def compact_index(
    store: SqlitePlaceStore, params: CompactParams | None = None, write: bool = True
) -> tuple[CompactPlaceIndex, IndexReport]:
    """The compact index over ``store``'s places, from the cache file (extended with places
    added since) or built; the file is (re)written when it changed and ``write``."""
    t0 = time.perf_counter()
    params = params or CompactParams()
    path = index_path(store.path, store.detector)
    index, why = None, "no index file"
    if path.exists():
        try:
            index, n_cached = _read(path, store, params)
            why = "" if index is not None else "stale (the map's places changed)"
        except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError) as error:
            why = f"damaged ({_one_line(error)})"
            n_cached = 0
        if why:
            _log.warning("index %s is %s; building it again from %s", path, why, store.path)
    if index is not None and lists_for(_total(store)) >= REBUILD_GROWTH * _lists(index):
        why, index = "outgrown (the map grew past its lists)", None
        _log.info("index %s is %s; building it again", path, why)
    if index is None:
        index = build_index(store, params)
        action, added = "built", len(store.place_ids)
    else:
        added = len(store.place_ids) - n_cached
        _extend(index, store, n_cached)
        action = "extended" if added else "read"
    if write and action != "read":
        _write(path, index, store)
    return index, IndexReport(action, added, why, time.perf_counter() - t0)


def refresh_index_files(db_path: Path) -> list[IndexReport]:
    """Bring every index file beside the map at ``db_path`` up to date with the map (after
    ``map add``: the new places encoded and added); a map without one is left without."""
    reports = []
    suffix = "-index.npz"
    for path in sorted(db_path.parent.glob(f"{db_path.name}.*{suffix}")):
        detector = path.name[len(db_path.name) + 1 : -len(suffix)]
        reports.append(compact_index(SqlitePlaceStore.open(db_path, detector))[1])
    return reports


def build_index(store: SqlitePlaceStore, params: CompactParams | None = None) -> CompactPlaceIndex:
    """Train a compact index on a sample streamed from ``store`` and add every place, in
    batches (never every descriptor at once)."""
    params = params or CompactParams()
    total = _total(store)
    sample = store.sample_descriptors(training_size(total, params), batch_places=BATCH_PLACES)
    index = CompactPlaceIndex.train(sample, params, n_descriptors=total)
    del sample
    _extend(index, store, 0)
    return index


def _total(store: SqlitePlaceStore) -> int:
    return int(store.keypoint_counts.sum())


def _lists(index: CompactPlaceIndex) -> int:
    return int(index.params.lists or 1)


def _extend(index: CompactPlaceIndex, store: SqlitePlaceStore, start: int) -> None:
    for batch in store.descriptor_batches(start, BATCH_PLACES):
        index.add_places(batch)


def _keys(store: SqlitePlaceStore) -> dict[str, np.ndarray]:
    catalog = store.catalog
    return {
        "place_ids": catalog.place_ids,
        "fingerprint_ids": catalog.fingerprint_ids,
        "image_keys": catalog.image_keys,
        "keypoint_counts": catalog.keypoint_counts,
    }


def _read(
    path: Path, store: SqlitePlaceStore, params: CompactParams
) -> tuple[CompactPlaceIndex | None, int]:
    """The cached index and how many of the store's places it holds, or ``(None, 0)`` if its
    places are not the store's first ones; ``ValueError`` (and zip errors) for a damaged file."""
    with np.load(path, allow_pickle=False) as data:
        header = json.loads(str(data["header"]))
        if header.get("format") != FORMAT or header.get("detector") != store.detector:
            return None, 0
        cached = {name: data[name] for name in _keys(store)}
        n = len(cached["place_ids"])
        if n > len(store.place_ids) or any(
            not np.array_equal(cached[name], now[:n]) for name, now in _keys(store).items()
        ):
            return None, 0
        index = CompactPlaceIndex.from_bytes(data["index"], cached["keypoint_counts"], params)
    if index.dim != store.descriptor_dim:
        return None, 0
    return index, n


def _write(path: Path, index: CompactPlaceIndex, store: SqlitePlaceStore) -> None:
    header = json.dumps({"format": FORMAT, "detector": store.detector})
    tmp = path.with_name(f"{path.name}.tmp{os.getpid()}-{threading.get_ident()}")
    try:
        with open(tmp, "wb") as out:
            arrays: dict[str, Any] = {"header": np.array(header), "index": index.to_bytes()}
            arrays |= _keys(store)
            np.savez(out, **arrays)
        os.replace(tmp, path)
    except OSError as error:
        tmp.unlink(missing_ok=True)
        _log.warning("index %s not written (%s); it is kept in memory", path, _one_line(error))


def _one_line(error: BaseException) -> str:
    text = str(error).strip()
    return text.splitlines()[0] if text else type(error).__name__
