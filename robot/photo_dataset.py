"""Render a panorama dataset of photo rooms (:mod:`robot.photo_room`) to a folder.

The folder has :mod:`robot.dataset`'s layout: ``manifest.csv`` (``image,room,x_m,y_m,heading_deg``
in each room's own frame), ``images/<room>_<k>.png``, ``render.json`` and a header-only
``edges.csv`` (photo rooms are not connected). Places are a grid of ``spacing_m`` kept
``margin_m`` off the walls, plus the capture point itself (first in each room, ``<room>_000``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from homing.bearings import wrap_angle_deg
from localizer.robot_protocol import Pose2D
from mapdb.dataset import ManifestEntry, write_edges, write_manifest
from robot.conditions import get_condition
from robot.dataset import prepare_folder
from robot.photo_library import load_photo, photo_room, photo_room_names
from robot.photo_room import CAPTURE_HEIGHT_M, PhotoRoom, render_photo_room
from robot.render import PanoramaCamera
from robot.world import grid_coordinates_m

PHOTO_SPACING_M = 1.5
PHOTO_MARGIN_M = 0.6
PHOTO_CAMERA = PanoramaCamera(1024, 512, height_m=CAPTURE_HEIGHT_M, projection="equirect")


def photo_places(
    room: PhotoRoom, spacing_m: float = PHOTO_SPACING_M, margin_m: float = PHOTO_MARGIN_M
) -> list[tuple[float, float]]:
    """Room-frame (x, y) places in metres: the capture point, then a centred grid of
    ``spacing_m`` kept ``margin_m`` off the walls (a grid point on the capture point is dropped)."""
    if not spacing_m > 0:
        raise ValueError(f"spacing_m must be positive, got {spacing_m}")
    places = [(float(room.capture_m[0]), float(room.capture_m[1]))]
    xs = grid_coordinates_m(room.size_m[0], margin_m, spacing_m)
    ys = grid_coordinates_m(room.size_m[1], margin_m, spacing_m)
    for y in ys:
        for x in xs:
            if math.hypot(x - places[0][0], y - places[0][1]) > 1e-6:
                places.append((round(float(x), 6), round(float(y), 6)))
    return places


def render_photo_dataset(
    out_dir: str | Path,
    rooms: Sequence[str] | None = None,
    spacing_m: float = PHOTO_SPACING_M,
    condition: str = "default",
    seed: int = 0,
    heading_deg: float | None = 0.0,
    camera: PanoramaCamera = PHOTO_CAMERA,
    grey: bool = False,
    overwrite: bool = False,
    progress: bool = True,
) -> Path:
    """Render every place of the photo rooms ``rooms`` (default: all shipped) into ``out_dir``;
    return the manifest path.

    ``heading_deg`` is every capture's heading in its room's frame, or None for seeded uniform
    random headings; ``seed`` also seeds the sensor noise. The condition's gain, gamma and noise
    apply, its added objects do not. ``ValueError`` naming the bad value for an unknown room or
    condition, a non-positive spacing, or a non-empty ``out_dir`` without ``overwrite``.
    """
    names = photo_room_names() if rooms is None else tuple(rooms)
    boxes = [photo_room(name) for name in names]
    cond = get_condition(condition)
    places = [(box, xy) for box in boxes for xy in photo_places(box, spacing_m)]
    out = Path(out_dir)
    prepare_folder(out, overwrite)
    rng = np.random.default_rng([seed, 1])
    rows: list[ManifestEntry] = []
    counts = dict.fromkeys(names, 0)
    for i, (box, (x_m, y_m)) in enumerate(tqdm(places, desc="photos", disable=not progress)):
        heading = float(rng.uniform(-180.0, 180.0)) if heading_deg is None else heading_deg
        heading = float(wrap_angle_deg(heading))
        pose = Pose2D(x_m, y_m, math.radians(heading))
        photo = load_photo(box.name)
        image = render_photo_room(photo, box, pose, camera, cond, seed=(seed, 2, i), grey=grey)
        name = f"images/{box.name}_{counts[box.name]:03d}.png"
        counts[box.name] += 1
        bgr = image if grey else cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        if not cv2.imwrite(str(out / name), bgr):
            raise OSError(f"could not write {out / name}")
        rows.append(ManifestEntry(name, out / name, box.name, x_m, y_m, round(heading, 6)))
    info = {"world": "photos", "rooms": [asdict(b) for b in boxes], "seed": seed}
    info |= {"condition": condition, "spacing_m": spacing_m, "camera": asdict(camera)}
    (out / "render.json").write_text(json.dumps(info, indent=2) + "\n")
    write_edges(out, [])
    return write_manifest(out, rows)
