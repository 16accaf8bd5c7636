"""Perturbed copies of a panorama dataset: each image rolled in yaw, resized, and put under a
capture condition (light and sensor noise), written as JPEG or PNG.

How would a map fare against views it did not store? From real photos (one capture point per
room, ``realdata/polyhaven``) the answer can only come from such copies: the same place at
another heading, in dimmer light, through a noisier sensor, at a camera's resolution, through
its compression. :func:`perturb_image` is pure; :func:`perturb_dataset` reads a dataset (a
manifest or one sub-folder per room) and writes the copies with a manifest.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from homing.bearings import wrap_angle_deg
from localizer.panorama_io import read_grey_image
from mapdb.dataset import ManifestEntry, read_dataset, read_edges, write_edges, write_manifest
from robot.conditions import DEFAULT_CONDITION, Condition, apply_photometric
from robot.dataset import prepare_folder


@dataclass(frozen=True)
class Perturbation:
    """What changes: ``roll_deg`` (the yaw roll, degrees, column 0 moving clockwise by it; None:
    a seeded uniform roll per image), ``width_px`` (the output width, the aspect kept; None:
    unchanged), ``condition`` (gain, gamma and noise of :mod:`robot.conditions`; its objects do
    not apply to a photo), ``jpeg_quality`` (1 to 100; None: lossless PNG)."""

    roll_deg: float | None = 0.0
    width_px: int | None = None
    condition: Condition = field(default=DEFAULT_CONDITION)
    jpeg_quality: int | None = 90

    def __post_init__(self) -> None:
        if self.roll_deg is not None and not math.isfinite(self.roll_deg):
            raise ValueError(f"roll_deg must be finite, got {self.roll_deg!r}")
        if self.width_px is not None and self.width_px < 16:
            raise ValueError(f"width_px must be at least 16, got {self.width_px!r}")
        if self.jpeg_quality is not None and not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be 1 to 100, got {self.jpeg_quality!r}")


def perturb_image(
    image: np.ndarray, roll_px: int, width_px: int | None, condition: Condition,
    rng: np.random.Generator,
) -> np.ndarray:  # fmt: skip
    """``image`` (grey uint8, a 360° panorama) resized to ``width_px`` (aspect kept; None:
    as is), rolled right by ``roll_px`` columns (column ``c`` shows what column ``c - roll_px``
    showed), then under ``condition`` (noise drawn from ``rng``); grey uint8."""
    height, width = image.shape
    if width_px is not None and width_px != width:
        size = (width_px, max(1, round(height * width_px / width)))
        shrink = width_px < width
        image = cv2.resize(image, size, interpolation=cv2.INTER_AREA if shrink else cv2.INTER_CUBIC)
    rolled = np.roll(image, roll_px, axis=1)
    return apply_photometric(rolled.astype(np.float32), condition, rng)


def rolled_heading_deg(heading_deg: float | None, roll_px: int, width_px: int) -> float | None:
    """The heading (degrees, counter-clockwise) of column 0 after rolling right by ``roll_px``
    of ``width_px`` columns: the old heading turned counter-clockwise by the roll (columns run
    clockwise). None stays None."""
    if heading_deg is None:
        return None
    return round(float(wrap_angle_deg(heading_deg + 360.0 * roll_px / width_px)), 6)


def perturb_dataset(
    source: Path,
    out_dir: Path,
    perturbation: Perturbation,
    rooms: Sequence[str] | None = None,
    seed: int = 0,
    overwrite: bool = False,
    progress: bool = True,
) -> Path:
    """Write a perturbed copy of every image of the dataset ``source`` (of ``rooms`` only, if
    given) into ``out_dir/images`` with ``out_dir/manifest.csv`` (poses kept, headings turned
    by the roll) and the source's ``edges.csv`` between the rooms copied; returns the
    manifest's path. Image ``i`` draws its roll and noise from ``seed`` and ``i``.

    Raises ``ValueError`` for a room of ``rooms`` that ``source`` lacks (or an empty
    ``rooms``) and for an ``out_dir`` that holds images of ``source`` (it is cleared first),
    and the readers' errors (:class:`mapdb.errors.ManifestError`,
    :class:`localizer.panorama_io.PanoramaError`) naming the file.
    """
    entries = read_dataset(source)
    if rooms is not None:
        missing = sorted(set(rooms) - {e.room for e in entries})
        if missing or not rooms:
            raise ValueError(f"{source} has no room {', '.join(missing) or '(none given)'}")
        entries = [e for e in entries if e.room in rooms]
    inside = [e.image for e in entries if e.path.resolve().is_relative_to(out_dir.resolve())]
    if inside:  # --overwrite would delete them before they are read
        raise ValueError(f"{out_dir} holds images of {source} ({inside[0]}): choose another OUT")
    edges = read_edges(source)
    prepare_folder(out_dir, overwrite)
    suffix = ".png" if perturbation.jpeg_quality is None else ".jpg"
    params = [] if perturbation.jpeg_quality is None else [cv2.IMWRITE_JPEG_QUALITY,
                                                            perturbation.jpeg_quality]  # fmt: skip
    rows = []
    for i, entry in enumerate(tqdm(entries, desc="perturb", unit="pano", disable=not progress)):
        rng = np.random.default_rng([seed, i])
        image = read_grey_image(entry.path)
        width = perturbation.width_px or image.shape[1]
        roll_deg = perturbation.roll_deg
        roll_px = int(rng.integers(width)) if roll_deg is None else round(roll_deg / 360.0 * width)
        copy = perturb_image(image, roll_px, perturbation.width_px, perturbation.condition, rng)
        name = f"images/{i:04d}_{Path(entry.image).stem}{suffix}"
        if not cv2.imwrite(str(out_dir / name), copy, params):
            raise OSError(f"cannot write {out_dir / name}")
        heading = rolled_heading_deg(entry.heading_deg, roll_px, width)
        rows.append(ManifestEntry(name, out_dir / name, entry.room, entry.x_m, entry.y_m, heading))
    kept = {row.room for row in rows}
    edges = [(a, b) for a, b in edges if a in kept and b in kept]
    if edges:
        write_edges(out_dir, edges)
    return write_manifest(out_dir, rows)
