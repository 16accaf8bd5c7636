"""Feature extraction for building a map: a panorama file in, one fingerprint per preset out.

:func:`resolve_extractor` binds :func:`extract_panorama` to the chosen presets, giving the
picklable ``extract(path)`` that :func:`mapdb.build.build_map` runs in its worker processes.
The localizer is imported on first use, so importing this module stays light.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mapdb.build import Extractor
from mapdb.database import MapDatabase
from mapdb.records import Fingerprint

if TYPE_CHECKING:
    import numpy as np


def map_overrides(map_db: MapDatabase) -> dict[str, Any]:
    """The extraction settings a new place must take from the map's places to be comparable
    with them (:func:`localizer.features.matching_overrides`: a map written before contrast
    equalisation keeps none); nothing for an empty map."""
    from localizer.features import matching_overrides

    stored = map_db.stored_params()
    return {} if stored is None else matching_overrides(stored)


def extract_panorama(
    path: Path,
    presets: tuple[str, ...],
    camera: str = "auto",
    overrides: Mapping[str, Any] | None = None,
) -> list[Fingerprint]:
    """Read the panorama at ``path`` and extract one fingerprint per preset; ``camera`` is a
    ``--camera`` text (:func:`localizer.cameras.parse_camera`: ``auto`` reads a 2:1 image as
    equirectangular, an ``omni:...`` mirror image is unwrapped first); ``overrides`` are
    extraction parameters over the presets' (see :func:`map_overrides`).

    Raises ``localizer.panorama_io.PanoramaError`` (a ``ValueError``) naming a bad file, and
    ``localizer.cameras.NotPanoramaError`` (a ``ValueError``) naming an image whose size is no
    360° panorama's for ``camera``.
    """
    import cv2

    from localizer.panorama_io import read_panorama

    cv2.setNumThreads(1)  # one process per core already
    return extract_image(read_panorama(path), presets, camera, overrides, str(path))


def extract_image(
    image: np.ndarray,
    presets: tuple[str, ...],
    camera: str = "auto",
    overrides: Mapping[str, Any] | None = None,
    source: str = "image",
) -> list[Fingerprint]:
    """One fingerprint per preset of a decoded grey panorama ``image`` (what
    :func:`extract_panorama` does after reading the file; the map node's ``map/add`` calls it
    with the image it received); ``source`` names the image in errors."""
    from localizer.cameras import parse_camera
    from localizer.features import extract_with_camera

    spec = parse_camera(camera)
    return [
        extract_with_camera(image, spec, preset, source=source, **(overrides or {}))
        for preset in presets
    ]


def resolve_extractor(
    presets: tuple[str, ...], camera: str = "auto", overrides: Mapping[str, Any] | None = None
) -> Extractor:
    """The picklable ``extract(path)``: :func:`extract_panorama` bound to ``presets``, the
    ``camera`` text and ``overrides``."""
    return functools.partial(
        extract_panorama, presets=presets, camera=camera, overrides=dict(overrides or {})
    )
