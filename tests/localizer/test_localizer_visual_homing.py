"""Visual homing on fingerprints: the pure step on synthetic bearings, and closed loops."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from homing.alv import HomingError, alv_from_bearings
from localizer.robot_protocol import Capture, MoveResult, Pose2D
from localizer.verification import Verification
from localizer.visual_homing import (
    HomingParams,
    HomingProgress,
    StepParams,
    density_peak_rad,
    drive_home,
    grey_extractor,
    home_step,
    same_spot,
    signed_pose_direction_rad,
)
from mapdb.records import Fingerprint
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.worlds import make_world

WIDTH_PX = 1024


class LandmarkWorld:
    """Point landmarks on the walls of a 6 x 6 m room, each with its own random descriptor."""

    def __init__(self, seed: int, n: int = 60) -> None:
        rng = np.random.default_rng(seed)
        along, wall = rng.uniform(0.0, 6.0, n), rng.integers(0, 4, n)
        self.xy = np.where(
            (wall % 2 == 0)[:, None],
            np.column_stack([along, np.where(wall == 0, 0.0, 6.0)]),
            np.column_stack([np.where(wall == 1, 0.0, 6.0), along]),
        )
        self.descriptors = rng.uniform(0.0, 1.0, (n, 128)).astype(np.float32)

    def fingerprint(self, pose: Pose2D, visible: np.ndarray | None = None) -> Fingerprint:
        """The landmarks' bearings from ``pose`` in its robot frame, as a Fingerprint."""
        d = self.xy - [pose.x_m, pose.y_m]
        bearing = np.arctan2(d[:, 1], d[:, 0]) - pose.heading_rad
        bearing = np.mod(bearing + np.pi, 2 * np.pi) - np.pi
        x = np.mod(-bearing * WIDTH_PX / (2 * np.pi), WIDTH_PX)
        keep = np.ones(len(d), bool) if visible is None else visible
        xy = np.column_stack([x, np.full(len(x), 96.0)])
        return Fingerprint("sift", WIDTH_PX, 192, xy[keep], bearing[keep], self.descriptors[keep])


def _true_direction_rad(here: Pose2D, home: Pose2D) -> float:
    return math.atan2(home.y_m - here.y_m, home.x_m - here.x_m) - here.heading_rad


def _angle_error_deg(a_rad: float, b_rad: float) -> float:
    return abs(math.degrees(math.remainder(a_rad - b_rad, 2 * math.pi)))


def _cases(seed: int, count: int = 40, lo_m: float = 1.5, hi_m: float = 4.5):
    """Random landmark worlds with a home and a current pose (random headings) in them."""
    rng = np.random.default_rng(seed)
    for k in range(count):
        world = LandmarkWorld(k)
        home = Pose2D(*rng.uniform(lo_m, hi_m, 2), rng.uniform(-np.pi, np.pi))
        here = Pose2D(*rng.uniform(lo_m, hi_m, 2), rng.uniform(-np.pi, np.pi))
        yield world, home, here


def _rotation_rad(home: Pose2D, here: Pose2D) -> float:
    return math.remainder(home.heading_rad - here.heading_rad, 2 * math.pi)


@pytest.mark.parametrize("variant", ["thesis", "best"])
def test_step_with_known_rotation_points_within_90_deg_of_home(variant):
    # With every landmark seen in both views the ALV home vector is within 90 deg (Lambrinos).
    for world, home, here in _cases(7):
        step = home_step(
            world.fingerprint(here),
            world.fingerprint(home),
            StepParams(variant, outlier_deg=180.0),
            shift_rad=_rotation_rad(home, here),
        )
        assert _angle_error_deg(step.direction_rad, _true_direction_rad(here, home)) < 90.0


def test_best_step_with_unknown_rotation_points_within_90_deg_of_home():
    for world, home, here in _cases(8):
        step = home_step(world.fingerprint(here), world.fingerprint(home), StepParams("best"))
        assert _angle_error_deg(step.direction_rad, _true_direction_rad(here, home)) < 90.0


def test_best_step_recovers_a_pure_rotation():
    for world, home, here in _cases(11, count=10):
        turned = Pose2D(home.x_m, home.y_m, here.heading_rad)
        step = home_step(world.fingerprint(turned), world.fingerprint(home), StepParams("best"))
        assert step.shift_rad == pytest.approx(_rotation_rad(home, turned), abs=1e-9)
        assert step.length < 1e-9


def test_thesis_step_with_unknown_rotation_mostly_points_home():
    """The histogram compass sees only bearings: tested between near places."""
    errors = [
        _angle_error_deg(
            home_step(
                world.fingerprint(here), world.fingerprint(home), StepParams("thesis")
            ).direction_rad,
            _true_direction_rad(here, home),
        )
        for world, home, here in _cases(9, lo_m=2.5, hi_m=3.5)
    ]
    assert np.mean(np.array(errors) < 90.0) >= 0.9


def test_best_step_ignores_features_seen_only_in_one_view():
    world, home, here = next(_cases(10))
    rng = np.random.default_rng(3)
    seen_here, seen_home = rng.random(60) < 0.7, rng.random(60) < 0.7
    step = home_step(world.fingerprint(here, seen_here), world.fingerprint(home, seen_home))
    both = home_step(
        world.fingerprint(here, seen_here & seen_home),
        world.fingerprint(home, seen_here & seen_home),
    )
    assert step.home_xy == pytest.approx(both.home_xy)
    assert 0 < step.n_used <= int((seen_here & seen_home).sum())


def test_step_at_home_is_zero_with_no_parallax():
    world = LandmarkWorld(1)
    home = Pose2D(3.0, 3.0, 0.4)
    step = home_step(world.fingerprint(Pose2D(3.0, 3.0, -2.0)), world.fingerprint(home))
    assert step.length < 1e-9
    assert step.parallax_rad < 1e-9


def test_step_rejects_mismatched_detectors_and_empty_views():
    world = LandmarkWorld(1)
    fp = world.fingerprint(Pose2D(3.0, 3.0))
    other = Fingerprint(
        "mser", fp.image_width_px, fp.image_height_px, fp.keypoints_xy, fp.bearings_rad,
        fp.descriptors,
    )  # fmt: skip
    with pytest.raises(ValueError, match="'mser'"):
        home_step(other, fp)
    empty = Fingerprint.empty("sift", WIDTH_PX, 192)
    for variant in ("thesis", "best"):
        with pytest.raises(HomingError):
            home_step(empty, fp, StepParams(variant))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="'random'"):
        StepParams("random")  # type: ignore[arg-type]


def test_density_peak_finds_the_mode_across_the_seam():
    angles = np.r_[np.full(10, math.pi - 0.01), np.full(10, -math.pi + 0.02), [0.5, 1.0, -2.0]]
    peak = density_peak_rad(angles)
    assert abs(math.remainder(peak - math.pi, 2 * math.pi)) < math.radians(2)


class PointRobot:
    """A Robot in a LandmarkWorld: its captures are its pose, fingerprinted by ``extract``."""

    def __init__(self, pose: Pose2D, wall_x_m: float = math.inf) -> None:
        self.pose, self.wall_x_m = pose, wall_x_m

    def capture(self) -> Capture:
        return Capture(np.zeros((1, 1), np.uint8), 0.0, "point")

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        heading = self.pose.heading_rad + turn_rad
        x = self.pose.x_m + forward_m * math.cos(heading)
        bumped = x > self.wall_x_m
        s = (
            (self.wall_x_m - self.pose.x_m) / (x - self.pose.x_m) * forward_m
            if bumped
            else forward_m
        )
        self.pose = Pose2D(
            self.pose.x_m + s * math.cos(heading), self.pose.y_m + s * math.sin(heading), heading
        )
        return MoveResult(turn_rad, s, bumped)

    def odometry(self) -> Pose2D:
        return Pose2D(self.pose.x_m, self.pose.y_m, self.pose.heading_rad)

    def stop(self) -> None:
        """Moves are instantaneous here: nothing to stop."""


def test_drive_home_reaches_home_among_point_landmarks():
    world = LandmarkWorld(5)
    home = Pose2D(3.0, 3.0, 1.0)
    robot = PointRobot(Pose2D(1.5, 4.2, -2.5))
    result = drive_home(robot, world.fingerprint(home), lambda _: world.fingerprint(robot.pose))
    assert result.arrived, result
    assert math.hypot(robot.pose.x_m - home.x_m, robot.pose.y_m - home.y_m) < 0.25
    assert result.steps <= 40 and result.distance_m < 5.0


def test_arriving_needs_most_of_the_goals_view_matched():
    """A short home vector with little parallax from a handful of matches is not an arrival (in
    a bare room a few far features cancel that way metres from the goal)."""
    world = LandmarkWorld(5)
    home = Pose2D(3.0, 3.0, 1.0)
    few = np.arange(60) < 8  # 8 of the goal's 60 features in view: under 20 %
    robot = PointRobot(home)
    blind = drive_home(robot, world.fingerprint(home), lambda _: world.fingerprint(robot.pose, few))
    assert not blind.arrived and blind.steps > 0
    robot = PointRobot(home)
    seeing = drive_home(robot, world.fingerprint(home), lambda _: world.fingerprint(robot.pose))
    assert (seeing.arrived, seeing.reason, seeing.steps) == (True, "arrived", 0)
    with pytest.raises(ValueError, match="arrive_matched_fraction"):
        HomingParams(arrive_matched_fraction=1.5)


def test_drive_home_reports_each_capture_to_on_step():
    world = LandmarkWorld(5)
    home = Pose2D(3.0, 3.0, 1.0)
    robot = PointRobot(Pose2D(1.5, 4.2, -2.5))
    seen: list[HomingProgress] = []
    result = drive_home(
        robot,
        world.fingerprint(home),
        lambda _: world.fingerprint(robot.pose),
        on_step=seen.append,
    )
    assert result.arrived
    assert [p.home.length for p in seen if p.home is not None] == list(result.lengths)
    assert [p.steps for p in seen] == sorted(p.steps for p in seen)
    assert seen[0].steps == 0 and seen[0].distance_m == 0
    assert seen[-1].steps == result.steps and seen[-1].distance_m == result.distance_m
    assert seen[-1].view is result.last


def test_an_exception_in_on_step_ends_the_drive():
    world = LandmarkWorld(5)
    robot = PointRobot(Pose2D(1.5, 4.2, -2.5))

    def refuse(progress: HomingProgress) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        goal = world.fingerprint(Pose2D(3.0, 3.0, 1.0))
        drive_home(robot, goal, lambda _: world.fingerprint(robot.pose), on_step=refuse)
    assert robot.pose == Pose2D(1.5, 4.2, -2.5)


def test_drive_home_stops_blocked_behind_a_wall():
    world = LandmarkWorld(5)
    home = Pose2D(4.5, 3.0, 0.0)
    robot = PointRobot(Pose2D(1.5, 3.0, 0.0), wall_x_m=2.5)
    params = HomingParams(max_bumps=2)
    result = drive_home(
        robot, world.fingerprint(home), lambda _: world.fingerprint(robot.pose), params
    )
    assert (result.arrived, result.reason) == (False, "blocked")
    assert robot.pose.x_m <= 2.5 + 1e-9


@pytest.mark.parametrize("variant", ["best", "pose"])
def test_drive_home_in_the_rendered_square_room(variant):
    """Closed loop on 512 x 96 renders from 1.5 m away: ends within 0.3 m of the goal."""
    world = make_world("square", 0)
    camera = PanoramaCamera(512, 96)
    goal = Pose2D(2.5, 1.8, 0.4)
    extract = grey_extractor("sift")
    goal_fp = extract(SimulatedRobot(world, goal, camera=camera, grey=True).capture().image)
    robot = SimulatedRobot(world, Pose2D(1.2, 2.6, 2.0), camera=camera, grey=True)
    result = drive_home(robot, goal_fp, extract, HomingParams(step=StepParams(variant)))
    end = robot.true_pose
    assert math.hypot(end.x_m - goal.x_m, end.y_m - goal.y_m) < 0.3, result
    assert result.arrived


def _square_room_views(turn_rad: float, forward_m: float):
    """Two 512 x 96 views of the rendered square room: one, and one after the robot turned by
    ``turn_rad`` and drove ``forward_m``."""
    extract = grey_extractor("sift")
    robot = SimulatedRobot(
        make_world("square", 0), Pose2D(2.5, 1.8, 0.4), camera=PanoramaCamera(512, 96), grey=True
    )
    first = extract(robot.capture().image)
    robot.move(turn_rad, forward_m)
    return first, extract(robot.capture().image)


def test_a_view_turned_on_one_spot_is_told_to_be_from_that_spot():
    first, turned = _square_room_views(1.0, 0.0)
    assert same_spot(turned, first)


def test_a_view_a_metre_on_is_not_from_the_same_spot():
    first, moved = _square_room_views(0.0, 1.0)
    assert not same_spot(moved, first)


def test_views_of_different_detectors_are_not_told_to_be_from_one_spot():
    view = LandmarkWorld(1).fingerprint(Pose2D(3.0, 3.0))
    assert same_spot(view, view)
    assert not same_spot(replace(view, detector="mser"), view)


def _verification(yaw_rad: float, direction_rad: float) -> Verification:
    """A verified pose whose translation points along ``direction_rad`` (query frame)."""
    t = np.array([math.cos(direction_rad), math.sin(direction_rad), 0.0])
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    rotation = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # R_query_from_place
    return Verification(40, np.zeros((40, 2), dtype=np.int64), yaw_rad, rotation, t)


def _pose_case() -> tuple[float, float, np.ndarray, np.ndarray]:
    """A landmark world's home direction, the yaw between the views and their ALVs (all
    landmarks in view: the ALV home vector lies within 90 degrees of home)."""
    world, home, here = next(_cases(3))
    yaw = math.remainder(here.heading_rad - home.heading_rad, 2 * math.pi)
    alv_here = alv_from_bearings(world.fingerprint(here).bearings_rad)
    alv_home = alv_from_bearings(world.fingerprint(home).bearings_rad)
    return _true_direction_rad(here, home), yaw, alv_here, alv_home


def test_pose_direction_follows_the_cheirality_and_one_alv_against_the_other():
    truth, yaw, alv_here, alv_home = _pose_case()
    wrong_way = _verification(yaw, truth + math.pi)
    # the all-feature ALV (right here) and a cheirality vote for -t outvote the matched ALV
    direction = signed_pose_direction_rad(wrong_way, truth + math.pi, alv_here, alv_home, -1)
    assert _angle_error_deg(direction, truth) < 1e-6


def test_pose_direction_flips_an_axis_that_both_alvs_contradict():
    truth, yaw, alv_here, alv_home = _pose_case()
    wrong_way = _verification(yaw, truth + math.pi + 0.01)  # cheirality on the wrong side
    direction = signed_pose_direction_rad(wrong_way, truth + 0.3, alv_here, alv_home, 1)
    assert _angle_error_deg(direction, truth) == pytest.approx(math.degrees(0.01), abs=1e-6)


def test_pose_direction_keeps_the_axis_the_alvs_agree_with():
    truth, yaw, alv_here, alv_home = _pose_case()
    right_way = _verification(yaw, truth - 0.02)
    direction = signed_pose_direction_rad(right_way, truth - 0.4, alv_here, alv_home, 1)
    assert _angle_error_deg(direction, truth) == pytest.approx(math.degrees(0.02), abs=1e-6)


def test_pose_direction_takes_the_distances_side_against_the_three_other_votes():
    truth, yaw, alv_here, alv_home = _pose_case()
    wrong_way = _verification(yaw, truth + math.pi)
    # along a hall the cheirality and both ALVs can all be wrong (here: the matched ALV and the
    # cheirality, with the all-feature ALV turned the wrong way too); the change of distance
    # says the place lies behind the verified translation, and decides
    direction = signed_pose_direction_rad(
        wrong_way, truth + math.pi, -alv_here, -alv_home, 1, distance=-1
    )
    assert _angle_error_deg(direction, truth) < 1e-6
    without = signed_pose_direction_rad(wrong_way, truth + math.pi, -alv_here, -alv_home, 1)
    assert _angle_error_deg(without, truth) == pytest.approx(180.0)


def test_pose_direction_without_geometry_is_the_matched_direction():
    direction = signed_pose_direction_rad(Verification.none(), 1.2, np.ones(2), np.zeros(2), 0)
    assert direction == pytest.approx(1.2)
    nothing = signed_pose_direction_rad(Verification.none(), math.nan, np.ones(2), np.ones(2), 0)
    assert math.isnan(nothing)


def test_the_closed_loop_homes_as_eval_homings_best_does_by_default():
    from toploc.evaluation.homing import BEST_METHOD

    assert StepParams().variant == "pose"  # the verified axis, signed by vote
    assert BEST_METHOD == "pose-vote"
