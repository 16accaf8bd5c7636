"""A fake feature extractor for the map database tests: fast, deterministic, picklable.

``fake_extract(path, presets)`` decodes the image with OpenCV (a corrupt file raises
``ValueError`` naming it, like ``PanoramaError``) and returns one synthetic Fingerprint per preset,
seeded by the image bytes. ``slow_extract`` sleeps ``TOPLOC_FAKE_EXTRACT_DELAY_S`` seconds first
(so a test can kill a build mid-way). In-process CLI tests put ``fake_extract`` in place of
``toploc.extraction.extract_panorama`` (the ``fake_extractor`` fixture); a CLI subprocess runs
``python -m mapdb_cli_with_fake_extractor``.
"""

from __future__ import annotations

import hashlib
import os
import signal
import struct
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from mapdb.records import Fingerprint

N_KEYPOINTS = 24
DELAY_ENV = "TOPLOC_FAKE_EXTRACT_DELAY_S"


def fake_fingerprint(detector: str, width_px: int, height_px: int, seed: int) -> Fingerprint:
    """A synthetic fingerprint with ``N_KEYPOINTS`` keypoints on a W x H panorama."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform([0, 0], [width_px - 1, height_px - 1], size=(N_KEYPOINTS, 2))
    bearings = np.angle(np.exp(-2j * np.pi * xy[:, 0] / width_px))
    descriptors = rng.integers(0, 256, size=(N_KEYPOINTS, 128)).astype(np.float32)
    return Fingerprint(
        detector=detector,
        image_width_px=width_px,
        image_height_px=height_px,
        keypoints_xy=xy.astype(np.float32),
        bearings_rad=bearings,
        descriptors=descriptors,
        params={"detector": detector, "fake": True},
    )


def fake_extract(
    path: Path, presets: tuple[str, ...], camera: str = "auto", overrides: object = None
) -> list[Fingerprint]:
    """Decode ``path``; one fake fingerprint per preset (detector = preset up to the first '-')."""
    data = Path(path).read_bytes()
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise ValueError(f"{path}: corrupt or not an image ({len(data)} bytes)")
    seed = int.from_bytes(hashlib.sha256(data).digest()[:8], "little")
    height_px, width_px = image.shape
    return [
        fake_fingerprint(preset.split("-")[0], width_px, height_px, seed + i)
        for i, preset in enumerate(presets)
    ]


def slow_extract(
    path: Path, presets: tuple[str, ...], camera: str = "auto", overrides: object = None
) -> list[Fingerprint]:
    """``fake_extract`` after sleeping ``TOPLOC_FAKE_EXTRACT_DELAY_S`` seconds (default 0.2)."""
    time.sleep(float(os.environ.get(DELAY_ENV, "0.2")))
    return fake_extract(path, presets)


def first_slow_extract(path: Path, presets: tuple[str, ...]) -> list[Fingerprint]:
    """``fake_extract``, after half a second on images named ``*_000.png``: the first image of
    a build finishes after the ones behind it."""
    if Path(path).name.endswith("_000.png"):
        time.sleep(0.5)
    return fake_extract(path, presets)


def crashing_extract(path: Path, presets: tuple[str, ...]) -> list[Fingerprint]:
    """``fake_extract``, except that the worker process dies on images named ``*_003.png``."""
    if Path(path).name.endswith("_003.png"):
        os._exit(3)
    return fake_extract(path, presets)


def half_sending_extract(path: Path, presets: tuple[str, ...]) -> list[Fingerprint]:
    """``fake_extract``, except that on images named ``*_003.png`` the worker dies half-way
    through sending a result, as one the out-of-memory killer ends between the two writes of a
    large result: a length goes into the pool's result pipe, then ``SIGKILL``. The length, 1 GiB,
    is more than the other workers' results will fill, so the pool's reader never gets to the
    end of it (a short one is filled by the next results, which then fail to unpickle)."""
    if Path(path).name.endswith("_003.png"):
        frame = sys._getframe()
        while "result_queue" not in frame.f_locals:  # concurrent.futures' worker loop holds it
            frame = frame.f_back  # type: ignore[assignment]
        writer = frame.f_locals["result_queue"]._writer
        os.write(writer.fileno(), struct.pack("!i", 2**30))
        os.kill(os.getpid(), signal.SIGKILL)
    return fake_extract(path, presets)
