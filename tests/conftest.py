"""Fixtures shared by the test folders: a small rendered map of the ``building`` world; and
Hypothesis's profile."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest
from filelock import FileLock
from hypothesis import settings

# The property tests draw the same examples on every run ("ci", the default), so a red run is a
# regression anyone can reproduce, not a rare draw of that run: random draws found a planar
# RANSAC tie and a binning edge of the wedge vote, each once in a CI run. To look for new
# counterexamples: HYPOTHESIS_PROFILE=explore python -m pytest (then add what it finds).
settings.register_profile("ci", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

WIDTH_PX = 512
HEIGHT_PX = 96


@pytest.fixture(scope="session")
def building_map(tmp_path_factory: pytest.TempPathFactory, worker_id: str):
    """A small SIFT map of the rendered ``building`` world at 512 x 96 (spacing 1.5 m), with
    its room graph: ``(db_path, dataset_dir)``. Built once per run: the first xdist worker to
    ask builds it under the run's shared temporary folder while the others wait on its lock
    (tests only read it; a test that writes copies it first)."""
    base = tmp_path_factory.getbasetemp()  # the run's own; under xdist, this worker's in it
    root = (base if worker_id == "master" else base.parent) / "building"
    with FileLock(str(root) + ".lock"):
        if not (root / "built").exists():
            shutil.rmtree(root, ignore_errors=True)  # a half-built one from a killed worker
            _build_building_map(root)
            (root / "built").touch()
    return root / "map.db", root / "dataset"


def _build_building_map(root: Path) -> None:
    from mapdb.build import build_map
    from mapdb.database import MapDatabase
    from mapdb.dataset import read_edges, read_manifest
    from mapdb.graph import connect_known_rooms
    from robot.dataset import render_dataset
    from robot.render import PanoramaCamera
    from toploc.extraction import resolve_extractor
    from toploc.maps import calibrate_map

    dataset = root / "dataset"
    camera = PanoramaCamera(WIDTH_PX, HEIGHT_PX)
    render_dataset(dataset, "building", spacing_m=1.5, camera=camera, progress=False)
    db_path = root / "map.db"
    with MapDatabase.open(db_path) as map_db:
        build_map(
            map_db, read_manifest(dataset), resolve_extractor(("sift",)), workers=0, progress=False
        )
        connect_known_rooms(map_db, read_edges(dataset))
    calibrate_map(db_path, "sift")  # as `toploc map build` does


@pytest.fixture
def zbus():
    """Two real Zenoh sessions on 127.0.0.1 (``bus_helpers.Bus``), closed after the test."""
    from bus_helpers import Bus

    pair = Bus()
    yield pair
    pair.client.close()
    pair.server.close()
