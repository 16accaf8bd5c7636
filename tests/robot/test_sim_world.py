"""Preset worlds, capture places and capture conditions of the simulator."""

from __future__ import annotations

import numpy as np
import pytest

from localizer.robot_protocol import Pose2D
from robot.conditions import CONDITIONS, add_objects, get_condition, world_under
from robot.render import PanoramaCamera, cast_rays, render_panorama
from robot.scene import build_scene
from robot.world import Material, capture_places, shared_wall
from robot.worlds import WORLD_NAMES, make_world

SMALL = PanoramaCamera(256, 64)


@pytest.mark.parametrize("name", WORLD_NAMES)
def test_presets_are_deterministic_and_places_keep_clear(name: str) -> None:
    world = make_world(name, seed=4)
    assert world == make_world(name, seed=4)
    assert world != make_world(name, seed=5)
    places = capture_places(world)
    assert {p.room for p in places} == set(world.room_names)
    for place in places:
        room = world.room(place.room)
        margin = world.wall_clearance_m - 1e-9
        assert margin <= place.x_m <= room.size_m[0] - margin
        assert margin <= place.y_m <= room.size_m[1] - margin
        for box in room.furniture:
            inside_x = box.min_m[0] - 0.3 < place.x_m < box.max_m[0] + 0.3
            assert not (inside_x and box.min_m[1] - 0.3 < place.y_m < box.max_m[1] + 0.3)


def test_preset_sizes() -> None:
    assert make_world("lab").room("lab").size_m == (10.0, 11.0)
    assert make_world("square").room("square").size_m == (4.0, 3.4)
    assert make_world("corridor").room("corridor").size_m == (22.5, 2.2)
    building = make_world("building")
    assert len(building.rooms) >= 4 and len(building.doors) >= len(building.rooms) - 1


def test_look_alike_rooms_differ_only_by_name_and_origin() -> None:
    world = make_world("building", seed=7)
    a, b = world.room("office_a"), world.room("office_b")
    assert a.origin_m != b.origin_m
    assert (a.walls, a.floor, a.furniture, a.posters) == (b.walls, b.floor, b.furniture, b.posters)
    door_a = [d.center_m - a.origin_m[0] for d in world.doors if "office_a" in (d.room_a, d.room_b)]
    door_b = [d.center_m - b.origin_m[0] for d in world.doors if "office_b" in (d.room_a, d.room_b)]
    assert door_a == pytest.approx(door_b)


def test_grid_spacing_and_errors() -> None:
    world = make_world("square")
    assert len(capture_places(world, 0.25)) > len(capture_places(world, 0.5))
    xs = sorted({p.x_m for p in capture_places(world, 0.5)})
    assert np.allclose(np.diff(xs), 0.5)
    with pytest.raises(ValueError, match="spacing_m must be positive, got -1"):
        capture_places(world, -1.0)
    with pytest.raises(ValueError, match="unknown world 'attic'"):
        make_world("attic")
    with pytest.raises(ValueError, match="unknown texture 'velvet'"):
        Material("velvet")
    with pytest.raises(ValueError, match="unknown condition 'foggy'"):
        get_condition("foggy")


def test_shared_wall_between_neighbours() -> None:
    world = make_world("building")
    wall = shared_wall(world.room("corridor"), world.room("office_a"))
    assert wall is not None and (wall.axis, wall.coord_m, wall.lo_m, wall.hi_m) == (1, 2.2, 0, 4)
    assert shared_wall(world.room("office_a"), world.room("seminar")) is None


@pytest.fixture(scope="module")
def square_renders() -> dict[str, np.ndarray]:
    world = make_world("square")
    pose = Pose2D(2.0, 1.7, 0.3)
    renders = {}
    for name, condition in CONDITIONS.items():
        scene = build_scene(world_under(world, condition, seed=1))
        renders[name] = render_panorama(scene, pose, SMALL, condition, seed=1).astype(float)
    return renders


def test_lighting_conditions_change_brightness(square_renders: dict[str, np.ndarray]) -> None:
    default = square_renders["default"]
    assert square_renders["dim"].mean() < 0.6 * default.mean()
    assert square_renders["bright"].mean() > 1.2 * default.mean()
    assert (square_renders["bright"] == 255).mean() > (default == 255).mean()


def test_noise_condition_adds_noise(square_renders: dict[str, np.ndarray]) -> None:
    noise = square_renders["noisy"] - square_renders["default"]
    assert abs(noise.mean()) < 1.0
    assert noise.std() == pytest.approx(CONDITIONS["noisy"].noise_std, rel=0.15)
    assert np.array_equal(square_renders["dim"], np.rint(square_renders["dim"]))


def test_objects_condition_adds_boxes_clear_of_places() -> None:
    world = make_world("building")
    busy = world_under(world, get_condition("objects"), seed=3)
    assert busy == world_under(world, get_condition("objects"), seed=3)
    places = capture_places(world)
    for room, before in zip(busy.rooms, world.rooms, strict=True):
        added = room.furniture[len(before.furniture) :]
        assert len(added) == CONDITIONS["objects"].objects_per_room
        for box, place in ((b, p) for b in added for p in places if p.room == room.name):
            dx = max(box.min_m[0] - place.x_m, place.x_m - box.max_m[0])
            dy = max(box.min_m[1] - place.y_m, place.y_m - box.max_m[1])
            assert max(dx, dy) >= 0.1 - 1e-9  # the places of the plain world stay free
    place = places[0]
    pose = world.building_pose(place.room, Pose2D(place.x_m, place.y_m))
    labels = build_scene(busy).labels
    seen = {labels[q] for q in np.unique(cast_rays(build_scene(busy), pose, SMALL).quad_index)}
    assert any("/object" in label for label in seen)
    assert add_objects(world, 0) == world
