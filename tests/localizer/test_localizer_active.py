"""Active disambiguation on the small rendered building map with the simulated robot."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pytest
from robot_helpers import RobotWrapper

from localizer.active import ENDINGS, ActiveParams, localize_actively, top_two_alike
from localizer.belief import LocalizationState, RoomBelief
from localizer.last_looks import way_in_step
from localizer.loaded_map import LoadedMap
from localizer.localizer import Localizer
from localizer.looking_elsewhere import matched_bearing_rad, step_away_if_stuck
from localizer.robot_protocol import Capture, MoveResult, Pose2D, Robot
from localizer.visual_homing import CANCELLED, HomingResult, StepParams, drive_home
from mapdb.loading import load_snapshot
from mapdb.records import Leg
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.worlds import make_world

CAMERA = PanoramaCamera(512, 96)


@pytest.fixture(scope="module")
def localizer(building_map) -> Localizer:
    return Localizer(LoadedMap.from_snapshot(load_snapshot(building_map[0])))


@pytest.mark.parametrize("policy", ["separating", "most-likely"])
def test_a_robot_kidnapped_into_a_look_alike_office_ends_localized_there(localizer, policy):
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_b", seed=4, camera=CAMERA)
    beliefs = []
    result = localize_actively(localizer, robot, policy, on_belief=beliefs.append)
    assert result.final.top[0] == "office_b"
    assert result.final.state is LocalizationState.LOCALIZED
    assert result.ended == "settled"
    assert beliefs[0] == result.first and beliefs[-1] == result.final
    assert result.frames >= 1 + len(result.visits)
    if result.first.state is LocalizationState.AMBIGUOUS:
        assert result.visits, "an ambiguous first look must lead to a drive"
        assert any(b.state is LocalizationState.HOMING for b in beliefs)
    assert result.distance_m == pytest.approx(robot.distance_driven_m, abs=1e-6)


class BlindRobot:
    """Sees a blank wall wherever it is, and counts the moves it is asked for."""

    def __init__(self) -> None:
        self.moves = 0

    def capture(self) -> Capture:
        return Capture(np.full((96, 512), 200, np.uint8), 0.0, "blind")

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        self.moves += 1
        return MoveResult(turn_rad, forward_m, False)

    def odometry(self) -> Pose2D:
        return Pose2D(0.0, 0.0, 0.0)

    def stop(self) -> None:
        """Moves are instantaneous here: nothing to stop."""


def test_a_lost_robot_steps_away_and_looks_again_before_it_gives_up(localizer):
    robot = BlindRobot()
    result = localize_actively(localizer, robot, "most-likely", ActiveParams(lost_looks=3))
    assert result.final.state is LocalizationState.LOST
    assert robot.moves == result.looks_elsewhere == 3
    assert result.visits == () and result.frames == 4
    assert result.ended == "lost"


def test_a_lost_robot_allowed_no_look_elsewhere_does_not_move(localizer):
    robot = BlindRobot()
    result = localize_actively(localizer, robot, "most-likely", ActiveParams(lost_looks=0))
    assert result.final.state is LocalizationState.LOST and robot.moves == 0


def test_a_robot_woken_facing_nothing_finds_its_room_a_step_away(localizer):
    robot = StepAwayRobot(
        SimulatedRobot.kidnapped(make_world("building"), "kitchen", seed=3, camera=CAMERA)
    )
    result = localize_actively(localizer, robot, "separating")
    assert result.first.state is LocalizationState.LOST
    assert result.looks_elsewhere == 1
    assert result.final.top[0] == "kitchen" and result.final.state is not LocalizationState.LOST


class StepAwayRobot:
    """A simulated robot whose camera is covered until it first moves (woken facing a wall),
    all but its first ``open_columns`` columns (a narrow view of the room)."""

    def __init__(self, robot: SimulatedRobot, open_columns: int = 0) -> None:
        self.robot, self.moved, self.open_columns = robot, False, open_columns

    def capture(self) -> Capture:
        seen = self.robot.capture()
        if self.moved:
            return seen
        image = seen.image.copy()
        image[:, self.open_columns :] = 128
        return Capture(image, seen.stamp_s, "covered")

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        self.moved = True
        return self.robot.move(turn_rad, forward_m)

    def odometry(self) -> Pose2D:
        return self.robot.odometry()

    def stop(self) -> None:
        self.robot.stop()


def test_a_lost_robot_that_faintly_sees_a_place_homes_to_it_and_looks_again(localizer):
    robot = StepAwayRobot(
        SimulatedRobot.kidnapped(make_world("building"), "kitchen", seed=1, camera=CAMERA),
        open_columns=128,
    )
    first_look = localizer.observe(robot.capture().image).evidence.places
    faint = max(first_look, key=lambda item: item.spread_inliers)
    asked = []

    def home(place_id: int) -> HomingResult:
        asked.append(place_id)
        return drive_home(robot, localizer.map.fingerprint(place_id), localizer.extract)

    result = localize_actively(localizer, robot, "separating", home=home)
    assert result.first.state is LocalizationState.LOST
    assert asked[0] == faint.place_id and faint.room == "kitchen"
    assert result.looks_elsewhere == 1
    assert result.final.top[0] == "kitchen" and result.final.state is not LocalizationState.LOST


def test_a_lost_robot_whose_homing_drives_nowhere_steps_away_instead(localizer):
    robot = StepAwayRobot(
        SimulatedRobot.kidnapped(make_world("building"), "kitchen", seed=1, camera=CAMERA),
        open_columns=128,
    )

    def stay(place_id: int) -> HomingResult:
        last = localizer.extract(robot.capture().image)
        return HomingResult(True, 0, 0.0, "arrived", last)

    result = localize_actively(localizer, robot, "separating", home=stay)
    assert result.first.state is LocalizationState.LOST
    assert robot.moved, "a homing that drove nowhere gives no new view: the robot steps away"
    assert result.final.top[0] == "kitchen"


def test_a_lost_robot_steps_towards_the_features_its_look_matched(localizer):
    # the first look sees only columns 0-127 (bearings 0 to -90 degrees): what it verifies
    # lies there, and the homing drives nowhere
    robot = StepAwayRobot(
        SimulatedRobot.kidnapped(make_world("building"), "kitchen", seed=1, camera=CAMERA),
        open_columns=128,
    )
    first = localizer.observe(robot.capture().image)
    turns_deg = []

    def stay(place_id: int) -> HomingResult:
        return HomingResult(True, 0, 0.0, "arrived", first.fingerprint)

    class Recorded(RobotWrapper):
        def move(self, turn_rad: float, forward_m: float) -> MoveResult:
            turns_deg.append(np.degrees(turn_rad))
            return super().move(turn_rad, forward_m)

    localize_actively(localizer, Recorded(robot), "separating", home=stay)
    assert turns_deg[0] == pytest.approx(np.degrees(matched_bearing_rad(first)))
    assert -90.0 < turns_deg[0] < 0.0


def test_a_look_that_verified_nothing_gives_no_bearing_to_step_towards(localizer):
    blank = localizer.observe(BlindRobot().capture().image)
    assert matched_bearing_rad(blank) is None


class WalledRobot(BlindRobot):
    """A blind robot with a wall in front of it: its first move bumps at once."""

    def __init__(self) -> None:
        super().__init__()
        self.asked: list[tuple[float, float]] = []

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        self.asked.append((turn_rad, forward_m))
        bumped = len(self.asked) == 1
        return MoveResult(turn_rad, 0.0 if bumped else forward_m, bumped)


def test_a_lost_robot_that_bumps_at_once_steps_the_other_way(localizer):
    robot = WalledRobot()
    params = ActiveParams(lost_looks=1)
    result = localize_actively(localizer, robot, "most-likely", params)
    assert robot.asked == [
        (pytest.approx(np.radians(params.lost_turn_deg)), params.lost_step_m),
        (pytest.approx(np.pi), params.lost_step_m),
    ]
    assert result.distance_m == pytest.approx(params.lost_step_m)


def test_active_params_refuse_a_negative_budget():
    with pytest.raises(ValueError, match="lost_looks must be >= 0"):
        ActiveParams(lost_looks=-1)


def test_active_params_refuse_homing_a_lost_robot_to_a_place_it_matched_nothing_with():
    with pytest.raises(ValueError, match="lost_home_min_inliers >= 1"):
        ActiveParams(lost_home_min_inliers=0)


def test_no_targets_allowed_means_no_drive(localizer):
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=2, camera=CAMERA)
    result = localize_actively(localizer, robot, "most-likely", ActiveParams(max_targets=0))
    assert result.visits == () and robot.distance_driven_m == 0
    assert result.first.state is LocalizationState.AMBIGUOUS
    assert result.ended == "drive-limit"


class NowherePolicy:
    """A policy that finds no place telling the rooms apart (twins without counterparts)."""

    name = "nowhere"

    def choose(self, belief, evidence, places, context) -> None:
        return None


def test_an_ambiguous_belief_with_no_telling_place_says_so(localizer):
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=2, camera=CAMERA)
    result = localize_actively(localizer, robot, NowherePolicy())
    assert result.final.state is LocalizationState.AMBIGUOUS and result.visits == ()
    assert result.ended == "no-telling-place" and result.ended in ENDINGS


def test_a_cancelled_drive_ends_the_localization_and_says_so(localizer):
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=2, camera=CAMERA)

    def cancelled(place_id: int) -> HomingResult:
        return HomingResult(False, 0, 0.0, CANCELLED, localizer.map.fingerprint(place_id))

    result = localize_actively(localizer, robot, "most-likely", home=cancelled)
    assert len(result.visits) == 1 and result.ended == CANCELLED


def test_an_unknown_policy_is_refused_by_name(localizer):
    with pytest.raises(ValueError, match="unknown disambiguation policy 'nearest'"):
        localize_actively(localizer, BlindRobot(), "nearest")


class CountingRobot(RobotWrapper):
    """The simulated robot, counting its captures."""

    def __init__(self, robot: SimulatedRobot) -> None:
        super().__init__(robot)
        self.captures = 0

    def capture(self) -> Capture:
        self.captures += 1
        return self.robot.capture()


def test_a_drive_that_goes_nowhere_does_not_count_the_same_view_twice(localizer):
    # the robot already stands where each target's view is: homing arrives without moving
    robot = CountingRobot(
        SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=2, camera=CAMERA)
    )

    def stay(place_id: int) -> HomingResult:
        return HomingResult(True, 0, 0.0, "arrived", localizer.map.fingerprint(place_id))

    result = localize_actively(localizer, robot, "most-likely", home=stay)
    assert result.visits, "the first look must be ambiguous for this test to say anything"
    assert robot.captures == 1 and result.frames == 1
    assert result.final.as_dict() == pytest.approx(result.first.as_dict())


def test_places_on_one_spot_of_twin_rooms_are_driven_to_once(localizer):
    # the batch map's twin offices have a place at every spot of both: one drive looks at both
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=3, camera=CAMERA)
    result = localize_actively(localizer, robot, "separating")
    visited = [visit.place_id for visit in result.visits]
    assert visited, "the first look must be ambiguous for this test to say anything"
    for k, place_id in enumerate(visited):
        for earlier in visited[:k]:
            assert place_id not in localizer.same_spot_places(earlier)


def test_a_twin_place_on_the_grid_has_its_counterpart_on_its_spot(localizer):
    office_a = [p.id for p in localizer.map.places if p.room == "office_a"]
    same = {place_id: localizer.same_spot_places(place_id) for place_id in office_a}
    assert any(same.values())
    for partners in same.values():
        assert {localizer.map.place(p).room for p in partners} <= {"office_b"}


def test_a_route_check_is_folded_in_as_a_likelihood_per_room(localizer):
    localizer.reset()
    belief = localizer.update_rooms({"office_a": 9.0})
    assert belief.as_dict()["office_a"] == pytest.approx(9 * belief.as_dict()["office_b"])
    with pytest.raises(ValueError, match=r"no room \['attic'\]"):
        localizer.update_rooms({"attic": 2.0})
    with pytest.raises(ValueError, match="finite number >= 0"):
        localizer.update_rooms({"office_a": -1.0})


def test_the_top_two_rooms_are_alike_when_one_group_of_look_alikes_holds_both():
    """office_b looks like office_a and like the storage room: a group of three, read together,
    whose top two need not be a pair."""
    rooms = ("corridor", "office_a", "office_b", "storage")
    group = ((1, 2, 3),)

    def belief(*probabilities: float) -> RoomBelief:
        return RoomBelief.from_probabilities(rooms, np.array(probabilities))

    assert top_two_alike(belief(0.01, 0.33, 0.32, 0.34), rooms, group)  # storage, office_a
    assert not top_two_alike(belief(0.40, 0.30, 0.20, 0.10), rooms, group)  # corridor first
    assert not top_two_alike(belief(0.01, 0.33, 0.32, 0.34), rooms, ())


def test_a_drive_that_gives_up_brings_the_robot_back_to_where_it_looked(localizer):
    """A robot in office_a whose homing to places of other rooms drives off and gives up goes
    back to the place it last looked from, not left where the homing gave up."""
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=0, camera=CAMERA)
    calls: list[int] = []

    def home(place_id: int) -> HomingResult:
        calls.append(place_id)
        goal = localizer.map.fingerprint(place_id)
        if localizer.map.place(place_id).room != "office_a":
            moved = robot.move(np.pi / 2, 0.8)
            return HomingResult(False, 1, abs(moved.moved_m), "max_steps", goal)
        return drive_home(robot, goal, localizer.extract, ActiveParams().homing)

    result = localize_actively(localizer, robot, "separating", home=home)
    gave_up = [
        k for k, place_id in enumerate(calls) if localizer.map.place(place_id).room != "office_a"
    ]
    assert gave_up and gave_up[0] > 0, "a drive after a first arrival must give up"
    for k in gave_up:
        assert calls[k + 1] == calls[k - 1]  # back where it looked from
    assert robot.true_room() == "office_a"
    assert result.distance_m == pytest.approx(robot.distance_driven_m, abs=1e-6)


def test_drives_that_told_nothing_leave_the_budget_to_drives_that_tell(localizer):
    """Drives to office_b's places give up and come back: they do not spend the two drives
    allowed, so the robot drives more than twice, and at most twice to any purpose."""
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=0, camera=CAMERA)

    def home(place_id: int) -> HomingResult:
        goal = localizer.map.fingerprint(place_id)
        if localizer.map.place(place_id).room != "office_a":
            moved = robot.move(np.pi / 2, 0.8)
            return HomingResult(False, 1, abs(moved.moved_m), "max_steps", goal)
        return drive_home(robot, goal, localizer.extract, ActiveParams().homing)

    params = ActiveParams(max_targets=2)
    result = localize_actively(localizer, robot, "separating", params, home=home)
    told = [visit for visit in result.visits if visit.told]
    assert len(result.visits) > params.max_targets >= len(told)
    assert all(not visit.homing.arrived for visit in result.visits if not visit.told)
    assert result.ended == "drive-limit"


def _first_look_localized(localizer: Localizer) -> SimulatedRobot:
    """A robot in the kitchen whose first look is ``localized`` (the seed searched for)."""
    for seed in range(20):
        robot = SimulatedRobot.kidnapped(
            make_world("building"), "kitchen", seed=seed, camera=CAMERA
        )
        belief, _ = localizer.localize_once(robot.capture().image)
        if belief.state is LocalizationState.LOCALIZED and belief.top[0] == "kitchen":
            return robot
    raise AssertionError("no kidnapping into the kitchen was localized at its first look")


def test_a_localized_first_look_homes_to_its_rooms_best_matched_place_before_it_ends(localizer):
    robot = _first_look_localized(localizer)
    homed_to: list[int] = []

    def stay(place_id: int) -> HomingResult:  # arrives where it stands: no second frame
        homed_to.append(place_id)
        return HomingResult(True, 0, 0.0, "arrived", localizer.map.fingerprint(place_id))

    result = localize_actively(localizer, robot, "separating", home=stay)
    first_look = localizer.latest
    assert first_look is not None and result.first.state is LocalizationState.LOCALIZED
    kitchen = [item for item in first_look.evidence.places if item.room == "kitchen"]
    best = max(kitchen, key=lambda item: item.spread_inliers).place_id
    assert homed_to == [best]
    assert [visit.place_id for visit in result.visits] == [best]
    assert result.final.top[0] == "kitchen" and result.ended == "settled"


def test_a_localized_robot_ends_at_a_place_of_the_room_it_names(localizer):
    robot = _first_look_localized(localizer)
    result = localize_actively(localizer, robot, "separating")
    assert result.final.state is LocalizationState.LOCALIZED
    assert result.visits and result.visits[-1].room == result.final.top[0] == "kitchen"
    assert robot.true_room() == "kitchen"


def test_a_localized_first_look_may_be_taken_as_it_is(localizer):
    robot = _first_look_localized(localizer)
    result = localize_actively(localizer, robot, "separating", ActiveParams(end_at_place=False))
    assert result.visits == () and robot.distance_driven_m == 0
    assert result.final == result.first


class _MoveLog(RobotWrapper):
    """The simulated robot, noting the true (building-frame) pose before and after each move."""

    def __init__(self, robot: SimulatedRobot) -> None:
        super().__init__(robot)
        self.sim = robot
        self.moves: list[tuple[Pose2D, Pose2D]] = []

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        before = self.sim.true_pose
        moved = self.sim.move(turn_rad, forward_m)
        self.moves.append((before, self.sim.true_pose))
        return moved


def _entered_from(
    localizer: Localizer, place_id: int, way_in_rad: float, room: str = "corridor"
) -> Localizer:
    """``localizer``'s map with place ``place_id`` recorded at the end of a 2 m drive along
    ``way_in_rad`` (the place's room frame, which is the building's shifted) from a place of
    ``room`` (its pose moved to the drive's start)."""
    place = localizer.map.place(place_id)
    other = next(p for p in localizer.map.places if p.room == room and p.id != place_id)
    assert place.x_m is not None and place.y_m is not None
    ux, uy = np.cos(way_in_rad), np.sin(way_in_rad)
    start = replace(other, x_m=place.x_m - 2.0 * ux, y_m=place.y_m - 2.0 * uy)
    via = tuple((place.x_m - d * ux, place.y_m - d * uy) for d in np.arange(1.9, 0.05, -0.1))
    entered = replace(place, leg=Leg(start.id, via))
    swap = {start.id: start, entered.id: entered}
    places = tuple(swap.get(p.id, p) for p in localizer.map.places)
    return Localizer(replace(localizer.map, places=places))


def _kitchen_way_in(localizer: Localizer) -> tuple[SimulatedRobot, int, float]:
    """A kitchen robot localized at its first look, the kitchen place that look matched best
    and the bearing from that place to the kitchen's middle (room frame, radians)."""
    robot = _first_look_localized(localizer)
    localizer.localize_once(robot.capture().image)
    assert localizer.latest is not None
    kitchen = [item for item in localizer.latest.evidence.places if item.room == "kitchen"]
    place = localizer.map.place(max(kitchen, key=lambda item: item.spread_inliers).place_id)
    width_m, depth_m = make_world("building").room("kitchen").size_m
    assert place.x_m is not None and place.y_m is not None
    return robot, place.id, float(np.arctan2(depth_m / 2 - place.y_m, width_m / 2 - place.x_m))


def test_a_robot_localized_at_a_place_recorded_on_the_way_in_steps_further_in(localizer):
    robot, place_id, way_in = _kitchen_way_in(localizer)
    moves = _MoveLog(robot)
    entered = _entered_from(localizer, place_id, way_in)
    result = localize_actively(entered, moves, "separating")
    assert result.final.state is LocalizationState.LOCALIZED and result.final.top[0] == "kitchen"
    assert result.visits[-1].place_id == place_id
    assert entered.latest is not None and entered.latest.at_place is None  # looked past it
    before, after = moves.moves[-1]  # the last move is the step in, looked at and settled
    stepped_m = np.hypot(after.x_m - before.x_m, after.y_m - before.y_m)
    assert 0.3 < stepped_m <= ActiveParams().step_in_m + 0.05
    heading = np.arctan2(after.y_m - before.y_m, after.x_m - before.x_m)
    assert abs(np.remainder(heading - way_in + np.pi, 2 * np.pi) - np.pi) < np.radians(25)


class _DriftedOdometry(RobotWrapper):
    """The robot standing where it stands, its odometry turned by ``turn_rad`` and shifted by
    ``(dx_m, dy_m)``: how it reads after a long drive has drifted it."""

    def __init__(self, robot: SimulatedRobot, dx_m: float, dy_m: float, turn_rad: float) -> None:
        super().__init__(robot)
        self.dx_m, self.dy_m, self.turn_rad = dx_m, dy_m, turn_rad

    def odometry(self) -> Pose2D:
        pose = self.robot.odometry()
        cos, sin = np.cos(self.turn_rad), np.sin(self.turn_rad)
        return Pose2D(
            cos * pose.x_m - sin * pose.y_m + self.dx_m,
            sin * pose.x_m + cos * pose.y_m + self.dy_m,
            pose.heading_rad + self.turn_rad,
        )


def test_the_step_in_does_not_move_with_odometry_drifted_since_the_look_at_the_place(localizer):
    # a route check that ends back at the place reuses the look it took there before the check
    robot, place_id, way_in = _kitchen_way_in(localizer)
    entered = _entered_from(localizer, place_id, way_in)
    assert drive_home(robot, entered.map.fingerprint(place_id), entered.extract).arrived
    look = entered.observe(robot.capture().image)
    assert entered.update(replace(look, at_place=place_id, odometry=robot.odometry())).top[0] == (
        "kitchen"
    )

    def step_in_seen_by(seen_by: Robot) -> tuple[float, float]:
        """The step in's end: metres from the robot, and its bearing (rad) off the heading."""
        found = way_in_step(entered, seen_by, 0.5, StepParams(), set())
        assert found is not None
        frame, (x_m, y_m), _ = found
        here = frame.pose(seen_by.odometry())
        bearing_rad = np.arctan2(y_m - here.y_m, x_m - here.x_m) - here.heading_rad
        return float(np.hypot(x_m - here.x_m, y_m - here.y_m)), float(
            np.remainder(bearing_rad + np.pi, 2 * np.pi) - np.pi
        )

    steady = step_in_seen_by(robot)
    drifted = step_in_seen_by(_DriftedOdometry(robot, 1.0, -0.6, np.radians(40)))
    assert drifted == pytest.approx(steady, abs=0.02)


def test_a_place_recorded_on_a_drive_within_its_room_gives_no_step_in(localizer):
    robot, place_id, way_in = _kitchen_way_in(localizer)
    within = _entered_from(localizer, place_id, way_in, room="kitchen")
    result = localize_actively(within, robot, "separating")
    assert result.visits[-1].place_id == place_id
    assert within.latest is not None and within.latest.at_place == place_id  # looked there last


def test_a_step_in_of_zero_is_no_step(localizer):
    robot, place_id, way_in = _kitchen_way_in(localizer)
    entered = _entered_from(localizer, place_id, way_in)
    localize_actively(entered, robot, "separating", ActiveParams(step_in_m=0.0))
    assert entered.latest is not None and entered.latest.at_place == place_id


def test_active_params_refuse_a_step_in_that_is_not_a_distance():
    for bad in (-0.1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="step_in_m"):
            ActiveParams(step_in_m=bad)


def _office_a_routed_to_the_kitchen(localizer: Localizer) -> tuple[int, Localizer]:
    """An office_a place and ``localizer``'s map with a kitchen place recorded on a drive from
    it: the one route out of an office, to check office_a by."""
    office = next(p.id for p in localizer.map.places if p.room == "office_a")
    kitchen = next(p.id for p in localizer.map.places if p.room == "kitchen")
    return office, _entered_from(localizer, kitchen, 0.0, room="office_a")


def _stuck(localizer: Localizer, homed: list[int]) -> Callable[[int], HomingResult]:
    """A homing that gives up where it began, noting the places asked for in ``homed``."""

    def home(place_id: int) -> HomingResult:
        homed.append(place_id)
        return HomingResult(False, 0, 0.0, "converged", localizer.map.fingerprint(place_id))

    return home


def test_a_robot_whose_homing_to_a_checks_start_gives_up_where_it_began_steps_away(localizer):
    """A robot in office_a, both offices alike at its first look: the route check of an office
    starts with a homing to its place; one that gives up where it began (the robot woken
    between furniture and a wall) is followed by a step towards what the look matched, not by
    the next check from the same corner."""
    office, routed = _office_a_routed_to_the_kitchen(localizer)
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=0, camera=CAMERA)
    first = routed.observe(robot.capture().image)
    turns: list[tuple[float, float]] = []
    homed: list[int] = []

    class Recorded(RobotWrapper):
        def move(self, turn_rad: float, forward_m: float) -> MoveResult:
            turns.append((turn_rad, forward_m))
            return super().move(turn_rad, forward_m)

    params = ActiveParams()
    result = localize_actively(
        routed, Recorded(robot), "separating", params, home=_stuck(localizer, homed)
    )
    assert result.first.state is LocalizationState.AMBIGUOUS
    assert result.checks and not result.checks[0].started
    assert homed[0] == result.checks[0].start == office
    step_rad = matched_bearing_rad(first)
    assert step_rad is not None and turns, "the robot must step out of where it gave up"
    assert turns[0] == (pytest.approx(step_rad), params.lost_step_m)
    assert result.distance_m == pytest.approx(robot.distance_driven_m, abs=1e-6)


def test_a_check_that_could_not_start_is_tried_once_more_when_no_other_is_left(localizer):
    office, routed = _office_a_routed_to_the_kitchen(localizer)
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=0, camera=CAMERA)
    homed: list[int] = []
    result = localize_actively(routed, robot, "separating", home=_stuck(localizer, homed))
    assert [check.start for check in result.checks] == [office, office]
    assert not any(check.started for check in result.checks)
    assert result.final.state is LocalizationState.AMBIGUOUS


def test_a_step_out_turns_by_what_the_robot_turned_since_its_look_was_taken(localizer):
    """A look kept from an earlier arrival at a place was taken at another heading: the step
    towards what it matched is turned back by the turns made since, by its own odometry."""
    robot = SimulatedRobot.kidnapped(make_world("building"), "kitchen", seed=1, camera=CAMERA)
    look = replace(localizer.observe(robot.capture().image), odometry=Pose2D(0.0, 0.0, 0.0))
    seen_rad = matched_bearing_rad(look)
    assert seen_rad is not None
    walled = WalledRobot()  # its odometry: (0, 0) facing 0; its first move bumps
    walled.odometry = lambda: Pose2D(0.0, 0.0, np.pi / 2)  # type: ignore[method-assign]
    p = ActiveParams()
    stepped_m = step_away_if_stuck(
        walled, look, walled.odometry(), p.lost_stuck_m, p.lost_step_m, p.lost_turn_deg
    )
    expected = np.remainder(seen_rad - np.pi / 2 + np.pi, 2 * np.pi) - np.pi
    assert walled.asked[0] == (pytest.approx(expected), p.lost_step_m)
    assert stepped_m == pytest.approx(p.lost_step_m)  # bumped at once, then the other way
