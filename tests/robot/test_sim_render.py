"""Geometry of the panorama renderer: bearings, columns, occlusion, doors, look-alike rooms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from homing.bearings import bearing_rad_from_column, column_from_bearing
from localizer.robot_protocol import Pose2D
from robot.render import PanoramaCamera, cast_rays, render_panorama
from robot.scene import Scene, build_scene
from robot.world import Box, Door, Material, Room, World, capture_places
from robot.worlds import make_world

GREY = Material("grey")
SMALL = PanoramaCamera(256, 64)


def pole_world(x_m: float, y_m: float, half_m: float = 0.05) -> World:
    """A plain 6 x 6 m room with one red floor-to-ceiling pole centred at (x_m, y_m)."""
    pole = Box(
        "pole",
        (x_m - half_m, y_m - half_m, 0.0),
        (x_m + half_m, y_m + half_m, 2.5),
        Material("red"),
        Material("red"),
    )
    room = Room("room", (0.0, 0.0), (6.0, 6.0), 2.5, (GREY,) * 4, GREY, GREY, (pole,))
    return World("pole", (room,))


def circular_mean_column(columns: np.ndarray, width_px: int) -> float:
    angles = 2 * np.pi * columns / width_px
    mean = math.atan2(np.sin(angles).mean(), np.cos(angles).mean())
    return (mean * width_px / (2 * np.pi)) % width_px


def column_distance(a: float, b: float, width_px: int) -> float:
    d = abs(a - b) % width_px
    return min(d, width_px - d)


@given(x=st.floats(0.0, 1023.999), width=st.sampled_from([64, 256, 1000, 1024]))
def test_column_bearing_round_trip(x: float, width: int) -> None:
    x = x % width
    bearing = bearing_rad_from_column(x, width)
    assert -np.pi < bearing <= np.pi
    assert column_distance(float(column_from_bearing(bearing, width)), x, width) < 1e-6


@given(bearing=st.floats(-10.0, 10.0))
def test_bearing_convention_is_clockwise_columns(bearing: float) -> None:
    width = 360
    x = float(column_from_bearing(bearing, width))
    assert 0 <= x < width
    assert math.isclose(math.cos(bearing), math.cos(-2 * math.pi * x / width), abs_tol=1e-9)
    assert math.isclose(math.sin(bearing), math.sin(-2 * math.pi * x / width), abs_tol=1e-9)


def test_column_zero_is_heading_and_quarter_turn_right() -> None:
    assert column_from_bearing(0.0, 1024) == 0
    assert column_from_bearing(-math.pi / 2, 1024) == pytest.approx(256)  # right: clockwise
    assert column_from_bearing(math.pi / 2, 1024) == pytest.approx(768)  # left


@settings(max_examples=25, deadline=None)
@given(
    px=st.floats(0.8, 5.2),
    py=st.floats(0.8, 5.2),
    heading=st.floats(-math.pi, math.pi),
)
def test_landmark_renders_at_predicted_column(px: float, py: float, heading: float) -> None:
    camera_xy = (3.0, 3.0)
    distance = math.hypot(px - camera_xy[0], py - camera_xy[1])
    if distance < 0.8:
        return
    scene = build_scene(pole_world(px, py))
    camera = PanoramaCamera(1024, 8)
    image = render_panorama(scene, Pose2D(*camera_xy, heading), camera)
    red = image[:, :, 0].astype(int) > 2 * image[:, :, 1].astype(int) + 40
    columns = np.flatnonzero(red[4])
    assert len(columns) > 0
    bearing = math.atan2(py - camera_xy[1], px - camera_xy[0]) - heading
    expected = float(column_from_bearing(bearing, camera.width_px))
    observed = circular_mean_column(columns, camera.width_px)
    assert column_distance(observed, expected, camera.width_px) <= 1.0


def test_heading_rotation_rolls_columns() -> None:
    world = make_world("square")
    scene = build_scene(world)
    shift = 37
    pose = Pose2D(1.3, 2.1, 0.4)
    turned = Pose2D(1.3, 2.1, 0.4 + 2 * math.pi * shift / SMALL.width_px)
    a = cast_rays(scene, pose, SMALL).quad_index
    b = cast_rays(scene, turned, SMALL).quad_index
    assert np.mean(np.roll(a, shift, axis=1) == b) > 0.995
    image_a = render_panorama(scene, pose, SMALL).astype(int)
    image_b = render_panorama(scene, turned, SMALL).astype(int)
    assert np.mean(np.abs(np.roll(image_a, shift, axis=1) - image_b)) < 2.0


def brute_force_hit(scene: Scene, origin: np.ndarray, ray: np.ndarray) -> tuple[int, float]:
    """Nearest front-facing quad along ``ray`` by testing every quad: the obvious slow way."""
    best_q, best_t = -1, math.inf
    for q in range(scene.n_quads):
        axis = scene.axis[q]
        if ray[axis] * scene.normal_sign[q] >= 0:
            continue
        t = (scene.coord_m[q] - origin[axis]) / ray[axis]
        point = origin + t * ray
        inplane = [point[a] for a in range(3) if a != axis]
        inside = all(scene.lo_m[q, i] <= inplane[i] <= scene.hi_m[q, i] for i in range(2))
        if t > 1e-9 and inside and t < best_t:
            best_q, best_t = q, t
    return best_q, best_t


@pytest.mark.parametrize("world_name", ["lab", "building"])
def test_ray_casting_matches_brute_force(world_name: str) -> None:
    world = make_world(world_name)
    scene = build_scene(world)
    rng = np.random.default_rng(3)
    places = capture_places(world)
    for k in rng.choice(len(places), size=4, replace=False):
        place = places[k]
        pose = world.building_pose(place.room, Pose2D(place.x_m, place.y_m, rng.uniform(-3, 3)))
        hits = cast_rays(scene, pose, SMALL)
        for row, col in zip(rng.integers(0, 64, 40), rng.integers(0, 256, 40), strict=True):
            azimuth = hits.azimuth_rad[col]
            ray = np.array([math.cos(azimuth), math.sin(azimuth), hits.tan_elevation[row]])
            q, t = brute_force_hit(scene, hits.origin_m, ray)
            assert hits.t_m[row, col] == pytest.approx(t, rel=1e-9)
            if hits.quad_index[row, col] != q:  # only a tie may pick another quad
                assert math.isclose(t, hits.t_m[row, col], rel_tol=1e-9)


def test_door_lets_one_see_into_the_next_room() -> None:
    world = make_world("building")
    scene = build_scene(world)
    corridor = world.room_names.index("corridor")
    office = world.room_names.index("office_a")
    # office_a's door is at building x = 2.9 in its -y wall; look straight at it.
    pose = world.building_pose("office_a", Pose2D(2.9, 1.5, -math.pi / 2))
    hits = cast_rays(scene, pose, SMALL)
    horizon = SMALL.height_px // 2
    assert scene.room_index[hits.quad_index[horizon, 0]] == corridor
    assert hits.t_m[horizon, 0] > 1.5  # beyond the door, on the corridor's far wall
    assert scene.room_index[hits.quad_index[horizon, SMALL.width_px // 4]] == office
    closed = World(world.name, world.rooms, tuple(d for d in world.doors if d.room_b != "office_a"))
    closed_hits = cast_rays(build_scene(closed), pose, SMALL)
    assert closed.room_names[scene.room_index[closed_hits.quad_index[horizon, 0]]] == "office_a"


def test_look_alike_rooms_render_identically() -> None:
    world = make_world("building")
    scene = build_scene(world)
    a, b = world.room_names.index("office_a"), world.room_names.index("office_b")
    for place in [p for p in capture_places(world) if p.room == "office_a"][:4]:
        local = Pose2D(place.x_m, place.y_m, 0.7)
        hits_a = cast_rays(scene, world.building_pose("office_a", local), SMALL)
        hits_b = cast_rays(scene, world.building_pose("office_b", local), SMALL)
        own_a = scene.room_index[hits_a.quad_index] == a
        own_b = scene.room_index[hits_b.quad_index] == b
        assert np.array_equal(own_a, own_b)
        assert own_a.mean() > 0.8
        image_a = render_panorama(scene, world.building_pose("office_a", local), SMALL)
        image_b = render_panorama(scene, world.building_pose("office_b", local), SMALL)
        same = np.all(image_a == image_b, axis=2)
        assert same[own_a].mean() > 0.995


def test_pose_outside_rooms_is_rejected() -> None:
    scene = build_scene(make_world("square"))
    with pytest.raises(ValueError, match="outside every room"):
        render_panorama(scene, Pose2D(-1.0, 1.0), SMALL)


def test_camera_validation_and_output_types() -> None:
    with pytest.raises(ValueError, match="vfov_deg"):
        PanoramaCamera(vfov_deg=200.0)
    with pytest.raises(ValueError, match="size"):
        PanoramaCamera(4, 4)
    scene = build_scene(make_world("square"))
    grey = render_panorama(scene, Pose2D(2.0, 1.7), PanoramaCamera(128, 32, vfov_deg=60), grey=True)
    assert grey.shape == (32, 128) and grey.dtype == np.uint8
    rgb = render_panorama(scene, Pose2D(2.0, 1.7), SMALL)
    assert rgb.shape == (64, 256, 3) and rgb.dtype == np.uint8
    assert (cast_rays(scene, Pose2D(2.0, 1.7), SMALL).quad_index >= 0).all()


def test_world_rejects_bad_doors() -> None:
    rooms = make_world("building").rooms
    with pytest.raises(ValueError, match="share no wall"):
        World("bad", rooms, (Door("office_a", "seminar", 1.0),))
    with pytest.raises(ValueError, match="does not fit"):
        World("bad", rooms, (Door("corridor", "office_a", 3.9),))
