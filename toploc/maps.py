"""Maps for the shell: a database file loaded for the localizer, and the maps of the rendered
worlds, made on first use and kept in a cache folder.

:func:`load_map` reads a map once (``mapdb.loading``) and prepares it for the localizer (the
retrieval index). A map of ``ON_DISK_MIN_PLACES`` places or more is not held in memory: its
fingerprints are read from the file on demand and its index is the compact one kept beside the
map (:mod:`toploc.map_index`).

The demo and ``toploc sim kidnap`` need a map of a preset world: the world's dataset is rendered
(``robot.dataset``) and built into a SQLite map (``mapdb.build``) once, then reused. The cache
is ``$TOPLOC_HOME`` or ``~/.cache/toploc``; a half-made map (an interrupted first run) is
completed on the next, since rendering and building are both resumable.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from filelock import FileLock, Timeout
from tqdm import tqdm

from localizer.calibration import MAX_QUERIES, calibrate, motions_to_try
from localizer.evidence import EvidenceParams
from localizer.features import (
    CAMERA_DEFAULTS,
    PRESETS,
    ExtractionParams,
    params_from_preset,
)
from localizer.likelihood import RatioLikelihood
from localizer.loaded_map import LoadedMap
from mapdb.build import Status, build_map
from mapdb.database import MapDatabase
from mapdb.dataset import MANIFEST_NAME, read_edges, read_manifest
from mapdb.errors import EmptyMapError
from mapdb.graph import connect_known_rooms
from mapdb.loading import load_snapshot, open_for_reading
from mapdb.store import SqlitePlaceStore
from robot.dataset import render_dataset
from robot.render import PanoramaCamera
from robot.sim_robot import MotionNoise, SimulatedRobot
from robot.world import World
from toploc.extraction import map_overrides, resolve_extractor
from toploc.map_index import compact_index

HOME_ENV = "TOPLOC_HOME"
CACHE_LOCK_NAME = "making.lock"
"""The lock file in a cached world map's folder that :func:`ensure_world_map` holds."""

ON_DISK_MIN_PLACES = 1000
"""From this many places a map's fingerprints stay on disk and its shortlist is the compact
index (docs/speed.md, "Maps of 10,000 places": at 1,000 places it matched the FLANN index's
top-1 in a fiftieth of the memory)."""

STORAGES = ("auto", "memory", "disk")


def load_map(
    db_path: Path | str,
    detector: str = "sift",
    use_index: bool | None = None,
    storage: str = "auto",
) -> LoadedMap:
    """The map at ``db_path`` ready for a :class:`localizer.localizer.Localizer` (read once, the
    database closed again). ``storage``: ``"memory"`` (every fingerprint stacked in memory, a
    FLANN index), ``"disk"`` (fingerprints read on demand, the compact index from its cache
    file, built or extended as needed) or ``"auto"`` (disk from ``ON_DISK_MIN_PLACES`` places).
    ``use_index`` False: brute force (in memory only). Raises
    :class:`mapdb.errors.MapDatabaseError` with a one-line message for a map without
    ``detector`` fingerprints (``EmptyMapError``, also a ``ValueError``) and for a missing,
    locked or damaged file."""
    if storage not in STORAGES:
        raise ValueError(f"storage must be one of {', '.join(STORAGES)}, got {storage!r}")
    on_disk_from = {"auto": ON_DISK_MIN_PLACES, "memory": None, "disk": 0}[storage]
    if use_index is False:
        on_disk_from = None
    try:
        snapshot = load_snapshot(db_path, detector, on_disk_from)
    except EmptyMapError:
        check_detector(db_path, detector)  # say which detectors the map holds, if any
        raise
    if isinstance(snapshot.table, SqlitePlaceStore):
        index, _ = compact_index(snapshot.table)
        return LoadedMap.from_snapshot(snapshot, index=index)
    return LoadedMap.from_snapshot(snapshot, use_index)


def check_detector(db_path: Path | str, detector: str) -> None:
    """Raise :class:`mapdb.errors.EmptyMapError` naming the detectors the map at ``db_path``
    holds unless one is ``detector`` (a missing or damaged file: ``MapDatabaseError``); read
    only when a map turned out to have no ``detector`` place, so a load opens the file once."""
    with open_for_reading(Path(db_path)) as map_db:
        held = sorted(map_db.fingerprint_counts())
    if detector in held:
        return
    if not held:
        message = (
            f"map {db_path} has no places yet: build it first (toploc map build) or record "
            "some (toploc map record)"
        )
    else:
        known = sorted({params_from_preset(name).detector for name in PRESETS})
        how = (
            f"a map holds {detector} fingerprints when it is built with --detector {detector}"
            if detector in known
            else f"toploc's detectors are {', '.join(known)}"
        )
        message = (
            f"map {db_path} has no {detector!r} fingerprints: it holds {', '.join(held)} "
            f"(--detector {held[0]}; {how})"
        )
    raise EmptyMapError(message, db_path)


def calibrate_map(
    db_path: Path | str,
    detector: str = "sift",
    progress: bool = False,
    declare: tuple[str, str] | None = None,
) -> RatioLikelihood:
    """Fit the likelihood of ``detector``'s evidence on the map's own places (leave-one-out,
    :mod:`localizer.calibration`) and store it in the map; returns it. The look-alike pairs the
    user declared (the stored likelihood's, and ``declare``: one more) are kept. Raises
    ``ValueError`` if the map has no ``detector`` fingerprint, or if ``declare`` names a room
    the map lacks or the same room twice."""
    loaded = load_map(db_path, detector)
    declared = list(loaded.likelihood.declared) if loaded.likelihood is not None else []
    if declare is not None:
        missing = [room for room in declare if room not in loaded.rooms]
        if missing or declare[0] == declare[1]:
            why = f"no room {missing[0]!r}" if missing else "one room twice"
            raise ValueError(
                f"cannot declare {declare[0]} and {declare[1]} look-alikes in {db_path}: {why} "
                f"(its rooms: {', '.join(loaded.rooms)})"
            )
        declared.append(declare)
    queries = min(MAX_QUERIES, len(loaded.table.place_ids))
    total = queries * len(motions_to_try(EvidenceParams()))
    with tqdm(total=total, desc=f"calibrate {detector}", unit="query", disable=not progress) as bar:

        def tick() -> None:
            bar.update(1)

        likelihood, _ = calibrate(loaded, on_query=tick, declared=declared)
    with MapDatabase.open(db_path, create=False) as map_db:
        map_db.set_likelihood(detector, likelihood.to_json())
    return likelihood


def kidnapped_robot(
    world: World,
    room: str,
    seed: int,
    db_path: Path,
    motion_noise: float = 0.05,
    condition: str = "default",
) -> SimulatedRobot:
    """The simulated robot at a seeded random pose in ``room``, with a camera that captures
    panoramas of the same size as the map's (a map without places: the renderer's default
    size, 1024 x 192, as the robot node's sim camera) and ``motion_noise`` (fraction of each
    turn and drive)."""
    with MapDatabase.open(db_path, create=False, readonly=True) as map_db:
        places = map_db.places()
    camera = PanoramaCamera(height_m=world.camera_height_m)
    if places:
        camera = PanoramaCamera(
            places[0].image_width_px, places[0].image_height_px, height_m=world.camera_height_m
        )
    noise = MotionNoise(motion_noise, motion_noise)
    return SimulatedRobot.kidnapped(
        world, room, seed=seed, condition=condition, camera=camera, noise=noise
    )


def cache_dir() -> Path:
    """Where world maps are kept: ``$TOPLOC_HOME`` or ``~/.cache/toploc``."""
    return Path(os.environ.get(HOME_ENV) or Path.home() / ".cache" / "toploc")


def ensure_world_map(
    world: str,
    root: Path | None = None,
    detector: str = "sift",
    seed: int = 0,
    progress: bool = True,
) -> Path:
    """The map of the preset ``world`` (rendered with ``seed``, default condition), made if
    missing or made by an older toploc (:func:`outdated_cache_map`, said on stderr); returns
    the database path ``<root>/<world>-<seed>/map.db``.

    Made under the folder's lock file (:data:`CACHE_LOCK_NAME`): two toploc commands started
    at once on a fresh machine (``toploc sim kidnap`` twice, say) both made the map into one
    database, and one failed with ``table "rooms" already exists``; the second now waits,
    saying so on stderr, and then finds the map made."""
    folder = (root or cache_dir()) / f"{world}-{seed}"
    folder.mkdir(parents=True, exist_ok=True)
    lock = FileLock(folder / CACHE_LOCK_NAME)
    try:
        lock.acquire(timeout=0)
    except Timeout:
        _said_waiting(f"{folder}: another toploc is making this map; waiting for it")
        lock.acquire()
    try:
        return _ensure_world_map(world, folder, detector, seed, progress)
    finally:
        lock.release()


def _said_waiting(message: str) -> None:
    print(message, file=sys.stderr)


def _ensure_world_map(world: str, folder: Path, detector: str, seed: int, progress: bool) -> Path:
    """:func:`ensure_world_map`'s work in ``folder``, its lock held."""
    dataset, db_path = folder / "dataset", folder / "map.db"
    done_marker = folder / f"built-{detector}"
    if done_marker.exists() and db_path.exists():
        outdated = outdated_cache_map(db_path, detector)
        changed = None if outdated else changed_cache_map(db_path, dataset)
        if outdated is None and changed is None:
            _calibrate_once(db_path, detector, progress)
            return db_path
        why = (
            f"made by an older toploc ({outdated})"
            if outdated
            else f"not as toploc built it ({changed})"
        )
        print(f"{db_path}: {why}; making it again", file=sys.stderr)
        done_marker.unlink(missing_ok=True)
        for suffix in ("", "-wal", "-shm"):
            db_path.with_name(db_path.name + suffix).unlink(missing_ok=True)
    if not (dataset / MANIFEST_NAME).exists():
        render_dataset(dataset, world, seed=seed, overwrite=True, progress=progress)
    entries = read_manifest(dataset)
    with MapDatabase.open(db_path) as map_db:
        extractor = resolve_extractor((detector,), overrides=map_overrides(map_db))
        report = build_map(map_db, entries, extractor, progress=progress)
        if report.interrupted:
            raise KeyboardInterrupt
        connect_known_rooms(map_db, read_edges(dataset))
    failed = [o.image for o in report.outcomes if o.status is Status.FAILED]
    if failed:
        raise RuntimeError(f"{len(failed)} panorama(s) of {dataset} failed: {', '.join(failed)}")
    _calibrate_once(db_path, detector, progress)
    done_marker.touch()
    return db_path


def outdated_cache_map(db_path: Path, detector: str) -> str | None:
    """Why a cached world map (toploc's own, :func:`ensure_world_map`) is out of date, or None:
    its places were extracted otherwise than this version extracts them for their camera
    (before the contrast equalisation, say: its queries would follow the old settings), or its
    likelihood reads another count than this version's. A user's map is never remade (it
    outlives the code, and queries follow it); this one is toploc's and is made again."""
    with MapDatabase.open(db_path, create=False, readonly=True) as map_db:
        stored = map_db.stored_params(detector)
        model = map_db.likelihood(detector)
    if stored is None:
        return "it has no places"
    kind = str(stored.get("camera", "cylinder"))
    current = params_from_preset(detector, camera=kind, **CAMERA_DEFAULTS.get(kind, {}))
    if ExtractionParams.from_record(stored) != current:
        return "its places were extracted with other settings"
    if model is None:
        return None  # calibrated on first use
    try:
        count = RatioLikelihood.from_json(model).count
    except ValueError:
        return "its likelihood is of an older kind"
    return None if count == RatioLikelihood().count else "its likelihood reads another count"


def changed_cache_map(db_path: Path, dataset: Path) -> str | None:
    """How a cached world map differs from the one :func:`ensure_world_map` built from
    ``dataset``, or None: its place count is not its dataset's image count (places added to
    it, say by ``toploc map add --db`` on the cache file), or the dataset is gone."""
    if not (dataset / MANIFEST_NAME).exists():
        return f"its dataset {dataset} is gone"
    expected = len(read_manifest(dataset))
    with MapDatabase.open(db_path, create=False, readonly=True) as map_db:
        held = map_db.info().n_places
    if held != expected:
        return f"it holds {held} places, its dataset {expected}"
    return None


def _calibrate_once(db_path: Path, detector: str, progress: bool) -> None:
    """Calibrate the map's likelihood unless it has been by a version that looks for look-alike
    rooms (a cached map calibrated before that, or never, is calibrated again)."""
    with MapDatabase.open(db_path, create=False) as map_db:
        stored = map_db.likelihood(detector)
    if stored is None or "lookalikes" not in stored:
        calibrate_map(db_path, detector, progress)
