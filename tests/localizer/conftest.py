"""Panoramas built in code for the localizer tests (no files shipped)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from skimage import data

WIDTH_PX = 512
HEIGHT_PX = 96


def _grey(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image


def make_textured_panorama(width_px: int = WIDTH_PX, height_px: int = HEIGHT_PX) -> np.ndarray:
    """Four skimage photographs side by side, resized into a width x height grey panorama."""
    photos = [data.camera(), data.astronaut(), data.coins(), data.coffee()]
    tile_w = width_px // len(photos)
    tiles = [
        cv2.resize(_grey(p), (tile_w, height_px), interpolation=cv2.INTER_AREA) for p in photos
    ]
    return np.ascontiguousarray(np.hstack(tiles))


def make_blob_panorama(
    x_px: float, y_px: float, width_px: int = WIDTH_PX, height_px: int = HEIGHT_PX, sigma_px=4.0
) -> np.ndarray:
    """A white panorama with one dark Gaussian blob at (x, y), wrapped around the 360° seam."""
    yy, xx = np.mgrid[:height_px, :width_px].astype(float)
    dx = (xx - x_px + width_px / 2) % width_px - width_px / 2
    blob = np.exp(-(dx**2 + (yy - y_px) ** 2) / (2 * sigma_px**2))
    return np.clip(np.rint(255 - 200 * blob), 0, 255).astype(np.uint8)


@pytest.fixture(scope="session")
def textured() -> np.ndarray:
    return make_textured_panorama()


@pytest.fixture(scope="session")
def blank() -> np.ndarray:
    return np.full((HEIGHT_PX, WIDTH_PX), 255, dtype=np.uint8)


@pytest.fixture(scope="session")
def blob_panorama():
    """The factory ``make_blob_panorama(x_px, y_px, ...)``."""
    return make_blob_panorama


@pytest.fixture(scope="session")
def building_map(tmp_path_factory: pytest.TempPathFactory):
    """A small SIFT map of the rendered ``building`` world at 512 x 96 (spacing 1.5 m), with
    its room graph: ``(db_path, dataset_dir)``."""
    from mapdb.build import build_map
    from mapdb.database import MapDatabase
    from mapdb.dataset import read_edges, read_manifest
    from mapdb.graph import connect_known_rooms
    from robot.dataset import render_dataset
    from robot.render import PanoramaCamera
    from toploc.extraction import resolve_extractor

    root = tmp_path_factory.mktemp("building")
    dataset = root / "dataset"
    camera = PanoramaCamera(WIDTH_PX, HEIGHT_PX)
    render_dataset(dataset, "building", spacing_m=1.5, camera=camera, progress=False)
    db_path = root / "map.db"
    with MapDatabase.open(db_path) as map_db:
        build_map(
            map_db, read_manifest(dataset), resolve_extractor(("sift",)), workers=0, progress=False
        )
        connect_known_rooms(map_db, read_edges(dataset))
    return db_path, dataset
