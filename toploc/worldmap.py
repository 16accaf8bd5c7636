"""Maps of the rendered worlds, made on first use and kept in a cache folder.

The demo and ``toploc sim kidnap`` need a map of a preset world: the world's dataset is
rendered (``robot.dataset``) and built into a SQLite map (``mapdb.build``) once, then reused.
The cache is ``$TOPLOC_HOME`` or ``~/.cache/toploc``; a half-made map (an interrupted first
run) is completed on the next, since rendering and building are both resumable from scratch.
"""

from __future__ import annotations

import os
from pathlib import Path

from mapdb.build import Status, build_map
from mapdb.database import MapDatabase
from mapdb.dataset import read_edges, read_manifest
from robot.dataset import MANIFEST_NAME, render_dataset
from toploc.commands.map import resolve_extractor

HOME_ENV = "TOPLOC_HOME"


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
    missing; returns the database path ``<root>/<world>-<seed>/map.db``."""
    folder = (root or cache_dir()) / f"{world}-{seed}"
    dataset, db_path = folder / "dataset", folder / "map.db"
    done_marker = folder / f"built-{detector}"
    if done_marker.exists() and db_path.exists():
        return db_path
    if not (dataset / MANIFEST_NAME).exists():
        render_dataset(dataset, world, seed=seed, overwrite=True, progress=progress)
    entries = read_manifest(dataset)
    with MapDatabase.open(db_path) as map_db:
        report = build_map(map_db, entries, resolve_extractor((detector,)), progress=progress)
        if report.interrupted:
            raise KeyboardInterrupt
        known = {room.name for room in map_db.rooms()}
        for a, b in read_edges(dataset):
            if a in known and b in known:
                map_db.connect_rooms(a, b)
    failed = [o.image for o in report.outcomes if o.status is Status.FAILED]
    if failed:
        raise RuntimeError(f"{len(failed)} panorama(s) of {dataset} failed: {', '.join(failed)}")
    done_marker.touch()
    return db_path
