"""The simulated robot: motion, collisions with walls and furniture, doors, odometry, captures."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from localizer.robot_protocol import Pose2D, Robot
from robot.render import PanoramaCamera
from robot.sim_robot import MotionNoise, Obstacles, SimulatedRobot, random_free_pose
from robot.worlds import make_world

SMALL = PanoramaCamera(128, 24)


@pytest.fixture(scope="module")
def square():
    return make_world("square", 0)


@pytest.fixture(scope="module")
def building():
    return make_world("building", 0)


def _footprint(world, room: str, box: str) -> tuple[float, float, float, float]:
    r = world.room(room)
    b = next(b for b in r.furniture if b.name == box)
    (x0, y0), (x1, y1) = r.to_building(*b.min_m[:2]), r.to_building(*b.max_m[:2])
    return x0, y0, x1, y1


def test_is_a_robot(square):
    robot: Robot = SimulatedRobot(square, Pose2D(2.5, 1.8), camera=SMALL)
    assert isinstance(robot.odometry().x_m, float)


def test_turns_then_drives_exactly_without_noise(square):
    robot = SimulatedRobot(square, Pose2D(2.5, 1.8, 0.0), camera=SMALL)
    result = robot.move(math.pi / 2, 0.5)
    assert not result.bumped
    assert result.moved_m == pytest.approx(0.5)
    pose = robot.true_pose
    assert (pose.x_m, pose.y_m, pose.heading_rad) == pytest.approx((2.5, 2.3, math.pi / 2))
    odom = robot.odometry()
    assert (odom.x_m, odom.y_m, odom.heading_rad) == pytest.approx((0.0, 0.5, math.pi / 2))
    assert robot.distance_driven_m == pytest.approx(0.5)
    robot.move(math.pi, 0.3)  # and back down: negative y
    assert robot.true_pose.y_m == pytest.approx(2.0)


def test_stops_at_a_wall(square):
    robot = SimulatedRobot(square, Pose2D(3.0, 1.8, 0.0), camera=SMALL, radius_m=0.2)
    result = robot.move(0.0, 2.0)
    assert result.bumped
    assert 3.8 - 0.011 <= robot.true_pose.x_m <= 3.8  # the +x wall is at 4.0 m
    assert result.moved_m == pytest.approx(robot.true_pose.x_m - 3.0)


def test_stops_at_furniture(square):
    x0, _, x1, y1 = _footprint(square, "square", "table")
    start_y = y1 + 1.0
    robot = SimulatedRobot(square, Pose2D((x0 + x1) / 2, start_y, -math.pi / 2), camera=SMALL)
    result = robot.move(0.0, 2.0)
    assert result.bumped
    assert y1 + 0.2 - 1e-9 <= robot.true_pose.y_m <= y1 + 0.2 + 0.011  # within a path step
    assert robot.true_room() == "square"


def test_backing_into_a_wall_also_stops(square):
    robot = SimulatedRobot(square, Pose2D(3.0, 1.8, math.pi), camera=SMALL)
    assert robot.move(0.0, -2.0).bumped
    assert robot.true_pose.x_m == pytest.approx(3.8, abs=0.011)


def test_passes_a_door_but_not_the_wall_beside_it(building):
    door = next(d for d in building.doors if d.room_b == "office_a")
    through = SimulatedRobot(building, Pose2D(door.center_m, 1.0, math.pi / 2), camera=SMALL)
    assert through.true_room() == "corridor"
    result = through.move(0.0, 2.5)
    assert not result.bumped
    assert through.true_room() == "office_a"
    beside = SimulatedRobot(building, Pose2D(door.center_m - 1.2, 1.0, math.pi / 2), camera=SMALL)
    assert beside.move(0.0, 2.5).bumped
    assert beside.true_room() == "corridor"
    assert beside.true_pose.y_m == pytest.approx(2.2 - 0.2, abs=0.011)


def test_a_door_narrower_than_the_robot_blocks_it(building):
    door = next(d for d in building.doors if d.room_b == "office_a")
    wide = SimulatedRobot(
        building, Pose2D(door.center_m, 1.0, math.pi / 2), camera=SMALL, radius_m=0.5
    )
    assert wide.move(0.0, 2.5).bumped
    assert wide.true_room() == "corridor"


def _odometry_error_m(noise: MotionNoise, square) -> float:
    start = Pose2D(2.0, 1.9, 0.3)
    robot = SimulatedRobot(square, start, camera=SMALL, noise=noise, seed=4)
    for turn, forward in [(0.5, 0.4), (-1.2, 0.3), (2.0, 0.5), (1.0, 0.2)] * 2:
        robot.move(turn, forward)
    odom, truth = robot.odometry(), robot.true_pose
    c, s = math.cos(start.heading_rad), math.sin(start.heading_rad)
    x = start.x_m + c * odom.x_m - s * odom.y_m
    y = start.y_m + s * odom.x_m + c * odom.y_m
    return math.hypot(x - truth.x_m, y - truth.y_m)


def test_odometry_drifts_with_noise_only(square):
    assert _odometry_error_m(MotionNoise(), square) < 1e-9
    assert _odometry_error_m(MotionNoise(forward_frac=0.1, turn_frac=0.1), square) > 0.01


def test_kidnapped_pose_is_free_inside_the_room(building):
    poses = set()
    for seed in range(8):
        robot = SimulatedRobot.kidnapped(building, "office_b", seed=seed, camera=SMALL)
        pose = robot.true_pose
        assert robot.true_room() == "office_b"
        assert robot.obstacles.free(np.array([[pose.x_m, pose.y_m]]))[0]
        poses.add((round(pose.x_m, 6), round(pose.y_m, 6), round(pose.heading_rad, 6)))
    assert len(poses) == 8
    again = SimulatedRobot.kidnapped(building, "office_b", seed=3, camera=SMALL).true_pose
    assert (round(again.x_m, 6), round(again.y_m, 6), round(again.heading_rad, 6)) in poses


def test_kidnapped_names_an_unknown_room(building):
    with pytest.raises(ValueError, match="'attic'"):
        SimulatedRobot.kidnapped(building, "attic", seed=0)


def test_refuses_a_start_in_collision(square):
    x0, y0, x1, y1 = _footprint(square, "square", "table")
    with pytest.raises(ValueError, match=r"within 0\.2 m"):
        SimulatedRobot(square, Pose2D((x0 + x1) / 2, (y0 + y1) / 2), camera=SMALL)
    with pytest.raises(ValueError, match="outside"):
        SimulatedRobot(square, Pose2D(-1.0, 1.0), camera=SMALL)


def test_a_carried_robot_stands_where_it_was_put_and_its_odometry_never_knew(square):
    robot = SimulatedRobot(square, Pose2D(2.5, 1.8, 0.0), camera=SMALL)
    robot.move(0.0, 0.5)
    odometry = robot.odometry()
    robot.carry(Pose2D(3.0, 1.8, math.pi / 2))
    pose = robot.true_pose
    assert (pose.x_m, pose.y_m, pose.heading_rad) == pytest.approx((3.0, 1.8, math.pi / 2))
    assert robot.odometry() == odometry


def test_a_robot_cannot_be_carried_into_a_wall_or_out_of_the_world(square):
    robot = SimulatedRobot(square, Pose2D(2.5, 1.8, 0.0), camera=SMALL)
    with pytest.raises(ValueError, match=r"\(-1\.0, 1\.0\) m"):
        robot.carry(Pose2D(-1.0, 1.0))
    assert (robot.true_pose.x_m, robot.true_pose.y_m) == (2.5, 1.8)


def test_capture_has_the_camera_size(square):
    grey = SimulatedRobot(square, Pose2D(2.5, 1.8), camera=SMALL, grey=True).capture()
    assert grey.image.shape == (24, 128) and grey.image.dtype == np.uint8
    colour = SimulatedRobot(square, Pose2D(2.5, 1.8), camera=SMALL).capture()
    assert colour.image.shape == (24, 128, 3)
    assert colour.source == "sim:square"


def test_sensor_noise_differs_per_capture(square):
    noisy = SimulatedRobot(square, Pose2D(2.5, 1.8), camera=SMALL, condition="noisy", grey=True)
    first, second = noisy.capture(), noisy.capture()
    assert second.stamp_s > first.stamp_s
    assert np.any(first.image != second.image)
    clean = SimulatedRobot(square, Pose2D(2.5, 1.8), camera=SMALL, grey=True)
    assert np.array_equal(clean.capture().image, clean.capture().image)


def test_turning_in_place_rolls_the_panorama(square):
    robot = SimulatedRobot(square, Pose2D(2.5, 1.8, 0.0), camera=SMALL, grey=True)
    before = robot.capture().image.astype(int)
    robot.move(2 * math.pi * 32 / 128, 0.0)  # a quarter turn left: 32 columns
    after = robot.capture().image.astype(int)
    # the view ahead before (column 0) is now on the right (bearing -90 deg: column 32)
    assert np.abs(np.roll(before, 32, axis=1) - after).mean() < 2.0
    assert np.abs(before - after).mean() > 5.0


@pytest.fixture(scope="module")
def building_obstacles(building):
    return Obstacles.of(building, 0.2)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    room=st.sampled_from(["corridor", "office_a", "kitchen", "seminar", "storage"]),
    heading=st.floats(-math.pi, math.pi),
    distance=st.floats(-6.0, 6.0),
)
def test_a_drive_never_ends_in_collision(building_obstacles, seed, room, heading, distance):
    start = random_free_pose(building_obstacles, room, np.random.default_rng(seed))
    reach, bumped = building_obstacles.reach_m(start, heading, distance)
    assert abs(reach) <= abs(distance) + 1e-12 and reach * distance >= 0
    assert bumped == (abs(reach) < abs(distance))
    end = (start.x_m + reach * math.cos(heading), start.y_m + reach * math.sin(heading))
    assert building_obstacles.free(np.array([end]))[0]
