"""The bare ``house`` world, procedural textures and the ray caster's equirect projection."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from localizer.robot_protocol import Pose2D
from mapdb.dataset import read_edges, read_manifest
from robot.dataset import render_dataset
from robot.procedural_textures import PROCEDURAL_TEXTURES, procedural_texture
from robot.render import PanoramaCamera, cast_rays, render_panorama
from robot.scene import build_scene
from robot.world import Box, Material, Room, World, capture_places
from robot.worlds import WORLD_NAMES, make_world

ROOMS = ("hall", "bedroom_a", "bathroom_a", "bedroom_b", "bathroom_b", "living", "kitchen", "study")
EQUIRECT = PanoramaCamera(256, 128, height_m=1.4, projection="equirect")


def test_house_rooms_look_alike_pairs_and_places() -> None:
    world = make_world("house")
    assert "house" in WORLD_NAMES
    assert world.room_names == ROOMS
    assert world.camera_height_m == 1.4 and world.place_spacing_m == 1.5
    for a, b in (("bedroom_a", "bedroom_b"), ("bathroom_a", "bathroom_b")):
        room_a, room_b = world.room(a), world.room(b)
        assert room_a.origin_m != room_b.origin_m
        same = ("size_m", "height_m", "walls", "floor", "ceiling", "furniture", "posters")
        assert all(getattr(room_a, f) == getattr(room_b, f) for f in same)
        doors_a = [
            d.center_m - room_a.origin_m[0] for d in world.doors if a in (d.room_a, d.room_b)
        ]
        doors_b = [
            d.center_m - room_b.origin_m[0] for d in world.doors if b in (d.room_a, d.room_b)
        ]
        assert doors_a == pytest.approx(doors_b)
    places = capture_places(world)
    assert {p.room for p in places} == set(ROOMS)
    hall = sorted(p.x_m for p in places if p.room == "hall" and p.y_m == places[0].y_m)
    assert np.diff(hall) == pytest.approx(1.5)


def test_look_alike_rooms_differ_only_through_the_door() -> None:
    world = make_world("house")
    scene = build_scene(world)
    views = []
    for name in ("bedroom_a", "bedroom_b"):
        pose = world.building_pose(name, Pose2D(2.0, 1.05, -math.pi / 2))  # facing the door
        views.append(render_panorama(scene, pose, EQUIRECT).astype(int))
    diff = np.abs(views[0] - views[1]).max(axis=2) > 30
    assert 0 < diff.mean() < 0.1
    cols = np.flatnonzero(diff.any(axis=0))
    door_bearing = math.atan2(-1.05, 3.3 - 2.0) + math.pi / 2  # door at x 3.3 on the -y wall
    door_col = (-EQUIRECT.width_px * door_bearing / (2 * math.pi)) % EQUIRECT.width_px
    assert np.min(np.abs(cols - door_col)) < 20


def test_house_renders_at_1_4_m_with_bright_windows() -> None:
    world = make_world("house")
    scene = build_scene(world)
    pose = world.building_pose("living", Pose2D(3.0, 1.6, 0.0))
    hits = cast_rays(scene, pose, EQUIRECT)
    assert hits.origin_m[2] == 1.4
    image = render_panorama(scene, pose, EQUIRECT)
    labels = np.array(scene.labels)[np.maximum(hits.quad_index, 0)]
    window = np.char.endswith(labels, "window0") & (hits.quad_index >= 0)
    assert window.sum() > 50
    assert np.median(image[window].astype(int)) >= 250  # overexposed glass
    wall = np.char.endswith(labels, "wall-x") & (hits.quad_index >= 0)
    assert np.std(image[wall].astype(float)) < 20  # bare paint: nearly uniform


def test_procedural_textures_are_deterministic_and_tile() -> None:
    for name in PROCEDURAL_TEXTURES:
        a = procedural_texture(name, 64)
        assert a.shape == (64, 64, 3) and a.dtype == np.uint8
        assert np.array_equal(a, procedural_texture(name, 64))
    paint = procedural_texture("paint_sage", 128).astype(float)
    seam = np.abs(paint[:, 0] - paint[:, -1]).mean()
    inside = np.abs(paint[:, 60] - paint[:, 61]).mean()
    assert seam < 2 * inside + 1  # no jump where tiles meet
    with pytest.raises(ValueError, match="unknown procedural texture 'paint_pink'"):
        procedural_texture("paint_pink", 64)


def test_equirect_landmark_column_and_row() -> None:
    """A small red box centred at a known point: its pixels sit at column ``-W*bearing/(2 pi)``
    and row ``(H - 1)/2 - elevation * H / pi``."""
    grey = Material("grey")
    point = (4.5, 4.0, 2.2)
    box = Box("mark", (4.45, 3.95, 2.15), (4.55, 4.05, 2.25), Material("red"), Material("red"))
    room = Room("room", (0.0, 0.0), (6.0, 6.0), 3.0, (grey,) * 4, grey, grey, (box,))
    scene = build_scene(World("mark", (room,)))
    camera = PanoramaCamera(512, 256, height_m=1.4, projection="equirect")
    pose = Pose2D(2.0, 2.5, math.radians(-20.0))  # the mark 51 degrees left, 31 degrees up
    image = render_panorama(scene, pose, camera).astype(int)
    rows, cols = np.nonzero(image[..., 0] > 2 * image[..., 1] + 40)
    assert len(rows) > 0
    dx, dy, dz = point[0] - pose.x_m, point[1] - pose.y_m, point[2] - 1.4
    bearing = math.atan2(dy, dx) - pose.heading_rad
    elevation = math.atan2(dz, math.hypot(dx, dy))
    assert cols.mean() == pytest.approx((-512 * bearing / (2 * math.pi)) % 512, abs=1.0)
    assert rows.mean() == pytest.approx(255 / 2 - elevation * 256 / math.pi, abs=1.0)
    elevations = camera.model.elevation_rad(np.arange(camera.height_px))
    assert elevations[0] == pytest.approx(math.pi / 2 - math.pi / 512)
    with pytest.raises(ValueError, match="W = 2H"):
        PanoramaCamera(512, 192, projection="equirect")


def test_a_house_dataset_has_the_expected_manifest(tmp_path: Path) -> None:
    camera = PanoramaCamera(64, 32, height_m=1.4, projection="equirect")
    manifest = render_dataset(tmp_path / "ds", "house", 3.0, camera=camera, progress=False)
    rows = read_manifest(manifest.parent)
    places = capture_places(make_world("house"), 3.0)
    assert [(r.room, r.x_m, r.y_m, r.heading_deg) for r in rows] == [
        (p.room, p.x_m, p.y_m, 0.0) for p in places
    ]
    assert {r.room for r in rows} == set(ROOMS)
    assert ("bedroom_a", "hall") in read_edges(manifest.parent)
