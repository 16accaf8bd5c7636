"""Render a panorama dataset of a preset world to a folder (the I/O adapter of the simulator).

Layout of the folder::

    manifest.csv      image,room,x_m,y_m,heading_deg  (one row per panorama)
    images/<room>_<k>.png
    edges.csv         room_a,room_b  (one row per pair of rooms joined by a door)
    render.json       how it was rendered (world, seed, condition, spacing, camera)

``image`` is relative to the folder. ``x_m``, ``y_m`` and ``heading_deg`` are in the frame of the
place's room: origin at the room's floor corner of smallest building x and y, axes parallel to
the building axes (REP-103, heading counter-clockwise from the room's +x axis, in (-180, 180]).
The format is :mod:`mapdb.dataset`'s, written with its :func:`~mapdb.dataset.write_manifest` and
:func:`~mapdb.dataset.write_edges`; read a dataset back with :func:`mapdb.dataset.read_manifest`.
"""

from __future__ import annotations

import json
import math
import shutil
from collections import Counter
from dataclasses import asdict
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from homing.bearings import wrap_angle_deg
from localizer.robot_protocol import Pose2D
from mapdb.dataset import EDGES_NAME, MANIFEST_NAME, ManifestEntry, write_edges, write_manifest
from robot.conditions import get_condition, world_under
from robot.render import PanoramaCamera, render_panorama
from robot.scene import build_scene
from robot.world import capture_places
from robot.worlds import make_world


def prepare_folder(out_dir: Path, overwrite: bool) -> None:
    """Create ``out_dir``; refuse a non-empty one unless ``overwrite`` (then clear our files)."""
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(f"output path {str(out_dir)!r} exists and is not a folder")
    if out_dir.is_dir() and any(out_dir.iterdir()):
        if not overwrite:
            raise ValueError(
                f"output folder {str(out_dir)!r} is not empty; "
                "pass overwrite=True (--overwrite) to replace it"
            )
        shutil.rmtree(out_dir / "images", ignore_errors=True)
        for name in (MANIFEST_NAME, EDGES_NAME, "render.json"):
            (out_dir / name).unlink(missing_ok=True)
    (out_dir / "images").mkdir(parents=True, exist_ok=True)


def render_dataset(
    out_dir: str | Path,
    world_name: str,
    spacing_m: float | None = None,
    condition: str = "default",
    seed: int = 0,
    heading_deg: float | None = 0.0,
    camera: PanoramaCamera | None = None,
    grey: bool = False,
    overwrite: bool = False,
    progress: bool = True,
) -> Path:
    """Render a panorama at every capture place of a preset world; return the manifest path.

    ``spacing_m`` is the capture grid spacing (default: the world's); ``seed`` builds the world,
    places the condition's objects and seeds the sensor noise; ``heading_deg`` is the heading of
    every capture in room frames, or None for seeded uniform random headings; ``camera``
    defaults to a 1024 x 192 cylinder at the world's camera height. Raises
    ``ValueError`` naming the bad value for an unknown world or condition, a non-positive
    spacing, or a non-empty ``out_dir`` without ``overwrite``.
    """
    world = make_world(world_name, seed)
    cond = get_condition(condition)
    if spacing_m is not None and not spacing_m > 0:
        raise ValueError(f"spacing_m must be positive, got {spacing_m}")
    if heading_deg is not None and not math.isfinite(heading_deg):
        raise ValueError(f"heading_deg must be finite or None, got {heading_deg}")
    camera = camera or PanoramaCamera(height_m=world.camera_height_m)
    out = Path(out_dir)
    places = capture_places(world, spacing_m)
    prepare_folder(out, overwrite)
    scene = build_scene(world_under(world, cond, seed))
    rng = np.random.default_rng([seed, 1])
    per_room: Counter[str] = Counter()
    rows = []
    for i, place in enumerate(tqdm(places, desc=f"{world_name}/{condition}", disable=not progress)):
        heading = float(rng.uniform(-180.0, 180.0)) if heading_deg is None else heading_deg
        heading = float(wrap_angle_deg(heading))  # (-180, 180]
        pose = world.building_pose(place.room, Pose2D(place.x_m, place.y_m, math.radians(heading)))
        image = render_panorama(scene, pose, camera, cond, seed=(seed, 2, i), grey=grey)
        name = f"images/{place.room}_{per_room[place.room]:03d}.png"
        per_room[place.room] += 1
        bgr = image if grey else cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        if not cv2.imwrite(str(out / name), bgr):
            raise OSError(f"could not write {out / name}")
        rows.append(
            ManifestEntry(name, out / name, place.room, place.x_m, place.y_m, round(heading, 6))
        )
    _write_render_info(out, world_name, seed, condition, spacing_m or world.place_spacing_m, camera)
    edges = sorted({(min(d.room_a, d.room_b), max(d.room_a, d.room_b)) for d in world.doors})
    write_edges(out, edges)
    return write_manifest(out, rows)


def _write_render_info(
    out: Path, world: str, seed: int, condition: str, spacing_m: float, camera: PanoramaCamera
) -> None:
    info = {"world": world, "seed": seed, "condition": condition, "spacing_m": spacing_m}
    info["camera"] = asdict(camera)
    (out / "render.json").write_text(json.dumps(info, indent=2) + "\n")
