"""Panoramas built in code for the localizer tests (no files shipped)."""

from __future__ import annotations

import numpy as np
import pytest
from localizer_images import HEIGHT_PX, WIDTH_PX, make_blob_panorama, make_textured_panorama


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
