"""A robot whose turns in place are measured by its camera: the odometry a route is driven on
keeps the turn really made, where the wheels slipped."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from homing.bearings import wrap_angle_rad
from localizer.robot_protocol import Capture, MoveResult, Pose2D
from localizer.routes import DriveFrame, Route, drive_route
from localizer.turn_compass import MAX_TURN_ERROR_DEG, CompassedRobot
from localizer.visual_homing import StepParams, grey_extractor
from robot.render import PanoramaCamera
from robot.sim_robot import MotionNoise, SimulatedRobot
from robot.worlds import make_world

EXTRACT = grey_extractor("sift")


def look(capture: Capture):
    return EXTRACT(capture.image)


class SlippingRobot:
    """A robot standing in one spot whose panorama (``scene``, column 0 along its heading)
    turns with it; each turn really made is the commanded one times ``slip`` (its odometry
    reports the commanded one). ``blind``: its captures show nothing."""

    def __init__(self, scene: np.ndarray, slip: float, blind: bool = False) -> None:
        self.scene, self.slip, self.blind = scene, slip, blind
        self.true_heading_rad = 0.0
        self.pose = Pose2D(0.0, 0.0, 0.0)

    def capture(self) -> Capture:
        if self.blind:
            return Capture(np.full_like(self.scene, 128), 0.0, "blind")
        width = self.scene.shape[1]
        # a landmark at bearing b (counter-clockwise) is seen at b - heading: turning left
        # moves the scene toward the higher columns
        shift_px = round(self.true_heading_rad / (2 * math.pi) * width)
        return Capture(np.roll(self.scene, shift_px, axis=1), 0.0, "slipping")

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        self.true_heading_rad += turn_rad * self.slip
        x, y, heading = self.pose.x_m, self.pose.y_m, self.pose.heading_rad + turn_rad
        self.pose = Pose2D(
            x + forward_m * math.cos(heading), y + forward_m * math.sin(heading), heading
        )
        return MoveResult(turn_rad, forward_m, False)

    def odometry(self) -> Pose2D:
        return self.pose

    def stop(self) -> None:
        """Nothing to stop."""


def heading_error_deg(robot: CompassedRobot, bare: SlippingRobot) -> float:
    return math.degrees(float(wrap_angle_rad(robot.odometry().heading_rad - bare.true_heading_rad)))


@settings(deadline=None, max_examples=20)
@given(turn_deg=st.floats(20.0, 170.0), left=st.booleans(), slip=st.floats(0.85, 1.15))
def test_a_turn_that_slipped_is_measured_by_the_views_before_and_after(
    textured: np.ndarray, turn_deg: float, left: bool, slip: float
) -> None:
    bare = SlippingRobot(textured, slip)
    robot = CompassedRobot(bare, look, StepParams(), math.radians(15.0))
    robot.move(math.radians(turn_deg if left else -turn_deg), 0.0)
    assert abs(heading_error_deg(robot, bare)) < 1.5  # a 512-column panorama: 0.7° per column
    assert robot.views == 2  # before and after


def test_a_small_turn_keeps_the_odometrys_turn(textured: np.ndarray) -> None:
    bare = SlippingRobot(textured, 1.1)
    robot = CompassedRobot(bare, look, StepParams(), math.radians(15.0))
    robot.move(math.radians(10.0), 0.5)
    assert robot.corrections_rad == [] and robot.views == 0
    assert robot.odometry() == bare.odometry()


def test_views_that_do_not_match_keep_the_odometrys_turn(textured: np.ndarray) -> None:
    bare = SlippingRobot(textured, 1.1, blind=True)
    robot = CompassedRobot(bare, look, StepParams(), math.radians(15.0))
    robot.move(math.radians(90.0), 0.0)
    assert robot.corrections_rad == []
    assert robot.odometry().heading_rad == pytest.approx(math.radians(90.0))


def test_a_turn_measured_far_off_the_odometrys_is_not_believed(textured: np.ndarray) -> None:
    slip = 1.0 + 2 * MAX_TURN_ERROR_DEG / 90.0  # 90° told, 150° made: a scene that repeats, say
    bare = SlippingRobot(textured, slip)
    robot = CompassedRobot(bare, look, StepParams(), math.radians(15.0))
    robot.move(math.radians(90.0), 0.0)
    assert robot.corrections_rad == []


def test_the_drive_after_a_turn_that_slipped_goes_the_way_it_was_told(
    textured: np.ndarray,
) -> None:
    bare = SlippingRobot(textured, 1.1)
    robot = CompassedRobot(bare, look, StepParams(), math.radians(15.0))
    robot.move(math.radians(90.0), 2.0)  # really 99°, then 9° back (really 9.9°) with the drive
    assert math.degrees(bare.true_heading_rad) == pytest.approx(89.1, abs=1.0)
    here = robot.odometry()
    assert math.degrees(here.heading_rad) == pytest.approx(89.1, abs=1.5)
    assert (here.x_m, here.y_m) == pytest.approx((0.0, 2.0), abs=0.05)


def test_a_route_driven_with_the_compass_ends_where_it_should_despite_slipping_turns() -> None:
    world = make_world("square")  # 4 x 3.4 m, a cupboard in one corner
    camera = PanoramaCamera(512, 96, height_m=world.camera_height_m)
    start, end = (2.2, 0.6), (0.4, 3.0)
    route = Route(1, 2, start, ((3.4, 0.6), (3.4, 1.8), (0.4, 1.8), end), 6.6)
    ends: dict[float, list[float]] = {15.0: [], math.inf: []}
    for seed, compass_deg in itertools.product(range(3), ends):  # infinity: no compass
        bare = SimulatedRobot(
            world,
            Pose2D(*start, math.pi / 2),
            camera=camera,
            grey=True,
            seed=seed,
            noise=MotionNoise(0.0, 0.1),
        )
        robot = CompassedRobot(bare, look, StepParams(), math.radians(compass_deg))
        drive_route(robot, route, DriveFrame(Pose2D(*start, math.pi / 2), robot.odometry()))
        ends[compass_deg].append(math.dist((bare.true_pose.x_m, bare.true_pose.y_m), end))
    assert max(ends[15.0]) < 0.2
    assert np.mean(ends[math.inf]) > 3 * np.mean(ends[15.0])


def test_a_view_taken_where_the_robot_stands_starts_the_next_measured_turn(
    textured: np.ndarray,
) -> None:
    bare = SlippingRobot(textured, 1.1)
    robot = CompassedRobot(bare, look, StepParams(), math.radians(15.0))
    robot.seen(look(bare.capture()))  # a mark, say
    robot.move(math.radians(90.0), 0.0)
    assert robot.views == 1  # only the view after the turn
    assert abs(heading_error_deg(robot, bare)) < 1.5


def test_a_view_taken_before_the_robot_moved_is_not_used(textured: np.ndarray) -> None:
    bare = SlippingRobot(textured, 1.1)
    robot = CompassedRobot(bare, look, StepParams(), math.radians(15.0))
    robot.seen(look(bare.capture()))
    robot.move(0.0, 0.5)  # it moved since: the view is not from here
    robot.move(math.radians(90.0), 0.0)
    assert robot.views == 2
