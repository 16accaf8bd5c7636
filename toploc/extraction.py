"""Feature extraction for building a map: a panorama file in, one fingerprint per preset out.

:func:`resolve_extractor` binds :func:`extract_panorama` to the chosen presets, giving the
picklable ``extract(path)`` that :func:`mapdb.build.build_map` runs in its worker processes.
The localizer is imported on first use, so importing this module stays light.
"""

from __future__ import annotations

import functools
from pathlib import Path

from mapdb.build import Extractor
from mapdb.records import Fingerprint


def extract_panorama(path: Path, presets: tuple[str, ...]) -> list[Fingerprint]:
    """Read the cylindrical panorama at ``path`` and extract one fingerprint per preset.

    Raises ``localizer.panorama_io.PanoramaError`` (a ``ValueError``) naming a bad file.
    """
    import cv2

    from localizer.features import extract_preset
    from localizer.panorama_io import read_panorama

    cv2.setNumThreads(1)  # one process per core already
    image = read_panorama(path)
    return [extract_preset(image, preset) for preset in presets]


def resolve_extractor(presets: tuple[str, ...]) -> Extractor:
    """The picklable ``extract(path)``: :func:`extract_panorama` bound to ``presets``."""
    return functools.partial(extract_panorama, presets=presets)
