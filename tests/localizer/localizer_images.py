"""Panoramas built in code for the localizer tests (no files shipped)."""

from __future__ import annotations

import cv2
import numpy as np
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
