"""Maps recorded the way users record them: a few places per room, the twins' places at
different spots of their identical frames; and what the likelihood makes of their twins."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from robot_helpers import RobotWrapper

from localizer.active import ActiveParams, localize_actively
from localizer.belief import LocalizationState, RoomBelief, StateThresholds, top_two_ratio
from localizer.loaded_map import LoadedMap
from localizer.localizer import Localizer
from localizer.robot_protocol import Capture, MoveResult
from localizer.route_checks import RouteCheckParams, check_route
from localizer.route_choice import route_to_check
from localizer.routes import route_out
from localizer.visual_homing import HomingResult, drive_home
from mapdb.database import MapDatabase
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.worlds import make_world
from toploc.evaluation.recorded_maps import record_map
from toploc.maps import load_map

CAMERA = PanoramaCamera(512, 96)
ROOMS = ("corridor", "office_a", "office_b")


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """``building``'s corridor and twin offices, two places each, recorded with seed 0."""
    db = tmp_path_factory.mktemp("recorded") / "map.db"
    places = record_map(make_world("building"), 2, 0, db, rooms=ROOMS, camera=CAMERA)
    return db, places


def test_a_recorded_map_holds_k_places_per_room_posed_by_the_odometry(recorded):
    db, places = recorded
    with MapDatabase.open(db, create=False, readonly=True) as map_db:
        stored = map_db.places()
    assert sorted(p.room for p in stored) == sorted(ROOMS * 2)
    assert [p.id for p in stored] == [p.place_id for p in places]
    for room in ROOMS:
        first, second = (p for p in stored if p.room == room)
        assert (first.x_m, first.y_m, first.heading_deg) == (0.0, 0.0, 0.0)  # odometry starts
        assert 0.4 < math.hypot(second.x_m, second.y_m) < 1.6  # a short drive later


def test_a_recorded_map_connects_the_rooms_its_doors_join_and_is_calibrated(recorded):
    db, _ = recorded
    with MapDatabase.open(db, create=False, readonly=True) as map_db:
        assert sorted(map_db.edges()) == [("corridor", "office_a"), ("corridor", "office_b")]
        assert map_db.likelihood("sift") is not None


def test_a_recording_starts_from_an_empty_file(recorded):
    db, _ = recorded
    with pytest.raises(FileExistsError, match="starts from an empty file"):
        record_map(make_world("building"), 2, 0, db, rooms=ROOMS, camera=CAMERA)


def test_a_recording_names_a_room_the_world_lacks(tmp_path):
    with pytest.raises(ValueError, match=r"no room \['lab'\]"):
        record_map(make_world("building"), 1, 0, tmp_path / "m.db", rooms=("lab",))


def test_twins_recorded_at_different_spots_have_no_counterparts(recorded):
    likelihood = load_map(recorded[0]).likelihood
    assert likelihood is not None
    assert likelihood.lookalikes == (("office_a", "office_b"),)
    assert likelihood.counterparts == ()


def test_twins_mapped_at_the_same_spots_have_counterparts_there(building_map):
    # the batch map's grid is laid out in each room's frame: the twins' places coincide
    loaded = load_map(building_map[0])
    assert loaded.likelihood is not None
    assert loaded.likelihood.lookalikes == (("office_a", "office_b"),)
    position = {place.id: (place.room, place.x_m, place.y_m) for place in loaded.places}
    pairs = loaded.likelihood.counterparts
    assert pairs
    for a, b in pairs:
        (room_a, *spot_a), (room_b, *spot_b) = position[a], position[b]
        assert {room_a, room_b} == {"office_a", "office_b"}
        assert spot_a == pytest.approx(spot_b)


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_a_frame_from_one_twin_off_the_stored_spots_is_never_sure_of_either(recorded, seed):
    localizer = Localizer(load_map(recorded[0]))
    room = ("office_a", "office_b")[seed % 2]
    robot = SimulatedRobot.kidnapped(make_world("building"), room, seed=seed, camera=CAMERA)
    belief, _ = localizer.localize_once(robot.capture().image)
    probability = belief.as_dict()
    assert belief.state is not LocalizationState.LOCALIZED
    twins = np.array([probability["office_a"], probability["office_b"]])
    assert twins.max() / twins.min() < localizer.config.thresholds.localized_ratio


def test_map_info_advises_two_spots_in_twins_without_counterparts(recorded):
    from click.testing import CliRunner

    from toploc.cli import main

    result = CliRunner().invoke(main, ["map", "info", "--db", str(recorded[0])])
    assert result.exit_code == 0, result.output
    assert "look-alike rooms: office_a ~ office_b" in result.output
    assert "same two spots" in result.output
    assert "Record the drive from each through its door" in result.output  # or that


def test_map_info_says_where_twins_can_be_told_apart(building_map):
    from click.testing import CliRunner

    from toploc.cli import main

    result = CliRunner().invoke(main, ["map", "info", "--db", str(building_map[0])])
    assert result.exit_code == 0, result.output
    assert "look-alike rooms: office_a ~ office_b" in result.output
    assert "(counterparts)" in result.output and "same two spots" not in result.output


@pytest.fixture(scope="module")
def advised_by_eye(recorded, tmp_path_factory):
    """The recorded map plus one counterpart pair, office_b's place 0.15 m off office_a's spot."""
    import shutil

    from toploc.evaluation.recorded_maps import record_counterparts

    db = tmp_path_factory.mktemp("advised") / "map.db"
    shutil.copy(recorded[0], db)
    pair = record_counterparts(
        make_world("building"), [("office_a", "office_b")], 0, db, camera=CAMERA, spots=1,
        offset_m=0.15,
    )  # fmt: skip
    return db, pair


def test_a_counterpart_recorded_by_eye_stands_off_the_spot(advised_by_eye):
    _, (first, second) = advised_by_eye
    world = make_world("building")
    shift = np.subtract(world.room("office_b").origin_m, world.room("office_a").origin_m)
    miss = (
        np.subtract(
            (second.true_pose.x_m, second.true_pose.y_m), (first.true_pose.x_m, first.true_pose.y_m)
        )
        - shift
    )
    assert float(np.hypot(*miss)) == pytest.approx(0.15)


@pytest.fixture(scope="module")
def driven(tmp_path_factory):
    """The corridor and twin offices, two places each, recorded on one drive (seed 3)."""
    db = tmp_path_factory.mktemp("driven") / "map.db"
    world = make_world("building")
    places = record_map(world, 2, 3, db, rooms=ROOMS, camera=CAMERA, drive=True)
    return db, places


def test_a_drive_records_each_place_with_the_leg_from_the_one_before(driven):
    db, places = driven
    with MapDatabase.open(db, create=False, readonly=True) as map_db:
        stored = map_db.places()
    assert [p.id for p in stored] == [p.place_id for p in places]
    assert stored[0].leg is None
    for before, place in itertools.pairwise(stored):
        assert place.leg is not None and place.leg.from_place == before.id
        if place.room != before.room:  # through a door: the drive's odometry on the way
            assert place.leg.via_xy_m
    assert len({(p.x_m, p.y_m) for p in stored}) == len(stored)  # one frame, not one per room


def kidnapped_and_localized(db, room: str, seed: int):
    robot = SimulatedRobot.kidnapped(make_world("building"), room, seed=seed, camera=CAMERA)
    return robot, localize_actively(Localizer(load_map(db)), robot)


def test_twins_no_place_tells_apart_are_told_apart_by_a_recorded_route(driven_to_kitchen):
    # one kidnapping of ten on this map (seeds 4-8 into either office) that end right and
    # localized, eight in session 26; seed 7's robot in office_a homes from the end of
    # office_b's route into office_b, does not get back and ends ambiguous there
    robot, result = kidnapped_and_localized(driven_to_kitchen, "office_a", 6)
    assert result.first.state is LocalizationState.AMBIGUOUS
    assert result.checks, "the twins are checked by driving their recorded routes"
    assert result.final.top[0] == "office_a" == robot.true_room()  # and it came back
    assert all(check.back_room == "office_a" for check in result.checks if check.confirmed)
    assert result.final.state is LocalizationState.LOCALIZED
    assert result.distance_m >= sum(check.distance_m for check in result.checks)


def test_a_check_that_arrives_and_retraces_the_maps_route_back_settles(driven_to_kitchen):
    """A robot in office_b checks office_b by its route into the kitchen and arrives at once.
    At the kitchen's place its odometry is fixed in the map's frame; back through its own views
    it stands where the map has the place it began at: the way it came is the map's route, and
    it is in office_b, whichever office it started in. One check settles it (8 : 1 when only
    the arrival counted)."""
    robot, result = kidnapped_and_localized(driven_to_kitchen, "office_b", 4)
    [check] = result.checks
    assert check.confirmed and check.back_room == "office_b" and not check.afresh
    assert result.final.state is LocalizationState.LOCALIZED
    assert result.final.top[0] == "office_b" == robot.true_room()


@pytest.mark.parametrize(("room", "seed"), [("office_b", 4), ("office_a", 5), ("office_b", 6)])
def test_a_route_check_never_confirms_the_twin_nor_leaves_the_robot_sure_and_wrong(
    driven, room, seed
):
    robot, result = kidnapped_and_localized(driven[0], room, seed)
    assert not any(c.confirmed for c in result.checks if c.room != room)
    if result.final.state is LocalizationState.LOCALIZED:  # where the robot is now
        assert result.final.top[0] == robot.true_room()


class StuckRobot(RobotWrapper):
    """The simulated robot, whose moves all bump at once while ``stuck``."""

    def __init__(self, robot: SimulatedRobot) -> None:
        super().__init__(robot)
        self.stuck = False

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        if self.stuck:
            return MoveResult(turned_rad=0.0, moved_m=0.0, bumped=True)
        return self.robot.move(turn_rad, forward_m)


def test_a_route_that_stops_short_where_its_end_place_is_in_sight_confirms_nothing(driven):
    """A route driven from the look-alike does not fit it and can stop against a wall, a few
    metres short, where the end place is in sight: homing covers the rest at once. Here the
    routes out of the offices go nowhere (the robot is stuck) and homing to the corridor's place
    carries the robot there: the look names the corridor, the homing drove 0.3 m, but the
    odometry says the robot, in office_b, never left it. office_a's 6 m route into the corridor
    is not confirmed (office_b's, 1.9 m long, ends within the odometry's drift of where it
    stopped)."""
    db, places = driven
    loaded = load_map(db)
    localizer = Localizer(loaded)
    sim = SimulatedRobot.kidnapped(make_world("building"), "office_b", seed=5, camera=CAMERA)
    robot = StuckRobot(sim)
    true_pose = {place.place_id: place.true_pose for place in places}
    carried = []

    def home(place_id: int) -> HomingResult:
        robot.stuck = False
        if loaded.place(place_id).room == "corridor":
            sim.carry(true_pose[place_id])
            carried.append(place_id)
            return HomingResult(True, 1, 0.3, "arrived", localizer.extract(sim.capture().image))
        homed = drive_home(
            robot, loaded.fingerprint(place_id), localizer.extract, ActiveParams().homing
        )
        robot.stuck = homed.arrived  # the route out of the office that follows goes nowhere
        return homed

    result = localize_actively(localizer, robot, home=home)
    twins = [check for check in result.checks if check.room == "office_a" and check.started]
    assert twins and carried
    assert not any(check.confirmed for check in twins)


def map_info(db) -> str:
    from click.testing import CliRunner

    from toploc.cli import main

    result = CliRunner().invoke(main, ["map", "info", "--db", str(db)])
    assert result.exit_code == 0, result.output
    return result.output


def test_map_info_asks_for_a_drive_beyond_the_hall_both_twins_open_onto(driven):
    """Every drive out of the offices ends in the corridor, which both open onto."""
    output = map_info(driven[0])
    assert (
        "office_a ~ office_b; no frame tells them apart, and the drives recorded out of them "
        "end only in corridor"
    ) in output
    assert "Record the drive on from one of them into a room beyond" in output
    assert "or a drive to one" not in output  # no counterparts
    assert "each has a recorded drive" not in output and "same two spots" not in output


def test_map_info_says_a_twins_drive_beyond_the_hall_tells_them_apart(driven_to_kitchen):
    """office_b's drive goes on into the kitchen; office_a's ends in the corridor."""
    output = map_info(driven_to_kitchen)
    assert "office_a ~ office_b; no frame tells them apart, but each has a recorded drive" in (
        output
    )
    assert "end only in" not in output and "or a drive to one" not in output


@pytest.fixture(scope="module")
def one_place(tmp_path_factory):
    """The corridor and twin offices, one place each, recorded on one drive (seed 3)."""
    db = tmp_path_factory.mktemp("one_place") / "map.db"
    places = record_map(make_world("building"), 1, 3, db, rooms=ROOMS, camera=CAMERA, drive=True)
    return db, places


def twins_unknown(db) -> LoadedMap:
    """The map at ``db`` loaded as if the calibration had not found the twins (one place each
    gives it little to compare: a recorded house's bedrooms verified each other at 4-5 spread
    inliers, as chance does)."""
    loaded = load_map(db)
    assert loaded.likelihood is not None
    unknown = replace(loaded.likelihood, lookalikes=(), counterparts=())
    return replace(loaded, likelihood=unknown)


@pytest.fixture(scope="module")
def one_place_twins_unknown(one_place):
    return twins_unknown(one_place[0])


def test_a_room_of_one_place_is_checked_by_a_route_before_the_robot_is_sure_of_it(
    one_place_twins_unknown,
):
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_b", seed=2, camera=CAMERA)
    result = localize_actively(Localizer(one_place_twins_unknown), robot)
    assert result.final.state is LocalizationState.LOCALIZED
    assert result.final.top[0] == "office_b" == robot.true_room()
    assert [(check.room, check.confirmed) for check in result.checks] == [("office_b", True)]


def test_a_robot_in_a_twin_the_map_does_not_know_checks_the_other_once_the_check_misses(
    one_place_twins_unknown,
):
    """The check of office_b misses: what the frames said for it is taken back (they may be
    its unknown twin's), and the robot goes on to check the room now likeliest, its own."""
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=4, camera=CAMERA)
    localizer = Localizer(one_place_twins_unknown)
    result = localize_actively(localizer, robot)
    assert result.first.top[0] == "office_b"  # its place nearer the robot, in its own frame
    checks = [(check.room, check.confirmed) for check in result.checks]
    assert checks == [("office_b", False), ("office_a", True)]
    assert localizer.doubted == {"office_b"}  # later frames that look like it do not count
    assert result.final.top[0] == "office_a" == robot.true_room()


def test_a_room_of_one_place_the_robot_cannot_home_to_is_doubted(one_place_twins_unknown):
    """A robot in office_a whose first look favours office_b (its twin, unknown to the map)
    cannot home to office_b's one place, so the check cannot start: what the frames said for
    office_b is taken back (they may have come from a room that looks like it), and later
    frames do not favour it over the next room."""
    loaded = one_place_twins_unknown
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=4, camera=CAMERA)
    localizer = Localizer(loaded)
    assert localizer.update(localizer.observe(robot.capture().image)).top[0] == "office_b"
    start = next(p for p in loaded.places if p.room == "office_b")
    route = route_out(loaded.legs, loaded.places, start.id, {"office_a", "office_b"}, 20.0)
    assert route is not None

    def home(_place_id: int) -> HomingResult:
        return HomingResult(False, 1, 0.4, "converged", localizer.extract(robot.capture().image))

    params = ActiveParams()
    check, *_ = check_route(
        localizer, robot, home, start, route, None, params.routes, params.homing
    )
    assert not check.started
    assert localizer.doubted == {"office_b"}
    after = localizer.belief().as_dict()
    assert after["office_b"] <= max(p for room, p in after.items() if room != "office_b")


def test_checks_of_one_room_that_all_miss_count_once_and_leave_the_twins_even(driven):
    """A robot in office_a whose every route ends short of the route's end place (a door its
    homing does not pass): the misses come from one cause, not from chance each time."""
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=5, camera=CAMERA)
    localizer = Localizer(load_map(driven[0]))

    def home(place_id: int) -> HomingResult:
        stored = localizer.map.fingerprint(place_id)
        if localizer.map.place(place_id).room == "corridor":  # a route's end: never reached
            return HomingResult(False, 1, 0.5, "converged", stored)
        return HomingResult(True, 1, 0.5, "arrived", stored)  # its room's places: at once

    result = localize_actively(localizer, robot, home=home)
    assert abs(odds(result.first, "office_a", "office_b") - 1.0) < 0.01  # the twins: even
    misses = [(check.room, check.confirmed) for check in result.checks]
    assert misses.count(("office_a", False)) >= 2 and ("office_b", False) in misses
    # one miss of each twin, each folded in once: even again (0.82 for office_b when each
    # miss of office_a was folded in)
    assert abs(odds(result.final, "office_a", "office_b") - 1.0) < 0.05


def test_checks_of_one_room_that_all_arrive_count_once(driven):
    """A robot in office_a whose routes into office_b never start (its places not reached):
    office_a's checks both arrive, and pass together (the same end place, the same view), so
    the second tells nothing the first did not."""
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=5, camera=CAMERA)
    localizer = Localizer(load_map(driven[0]))

    def home(place_id: int) -> HomingResult:
        goal = localizer.map.fingerprint(place_id)
        if localizer.map.place(place_id).room == "office_b":
            return HomingResult(False, 1, 0.5, "converged", goal)
        return drive_home(robot, goal, localizer.extract, ActiveParams().homing)

    result = localize_actively(localizer, robot, home=home)
    assert abs(odds(result.first, "office_a", "office_b") - 1.0) < 0.01  # the twins: even
    arrived = [check.room for check in result.checks if check.confirmed]
    assert arrived.count("office_a") >= 2
    # one route's worth of evidence (64 when each arrival was folded in), at the rates of a
    # hall both twins open onto: every route of either office ends in the corridor
    params = ActiveParams().routes
    once = params.hall_route_hit_rate / params.hall_route_false_rate  # 1.6 (8 before)
    assert odds(result.final, "office_a", "office_b") == pytest.approx(once, rel=0.05)


@pytest.fixture(scope="module")
def driven_to_kitchen(tmp_path_factory):
    """The corridor, the twin offices and the kitchen, two places each, recorded on one drive
    in that order (seed 3): office_a's routes end in the corridor, office_b's in the kitchen."""
    db = tmp_path_factory.mktemp("driven_kitchen") / "map.db"
    rooms = (*ROOMS, "kitchen")
    record_map(make_world("building"), 2, 3, db, rooms=rooms, camera=CAMERA, drive=True)
    return db


def test_twins_are_checked_first_by_a_route_that_ends_beyond_the_hall_they_share(
    driven_to_kitchen,
):
    """Both offices open onto the corridor: a route into it, driven from the other office,
    ends in the corridor too, an office's offset along it; one on into the kitchen does not
    reach the kitchen from the other office."""
    loaded = load_map(driven_to_kitchen)
    assert (
        loaded.likelihood is not None and ("office_a", "office_b") in loaded.likelihood.lookalikes
    )
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=5, camera=CAMERA)
    result = localize_actively(Localizer(loaded), robot)
    first = result.checks[0]
    assert loaded.place(first.end).room == "kitchen"
    assert first.confirmed is (first.room == "office_a")


class SlippingRobot(RobotWrapper):
    """The simulated robot, whose turns all go ``slip`` of the turn too far; its odometry has
    the turn it was told."""

    def __init__(self, robot: SimulatedRobot, slip: float) -> None:
        super().__init__(robot)
        self.sim, self.slip = robot, slip

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        turned = self.sim.move(turn_rad, 0.0)
        pose = self.sim.true_pose
        self.sim.carry(replace(pose, heading_rad=pose.heading_rad + self.slip * turn_rad))
        moved = self.sim.move(0.0, forward_m)
        return MoveResult(turned.turned_rad, moved.moved_m, moved.bumped)


@pytest.mark.parametrize(("compass_deg", "arrives"), [(15.0, True), (math.inf, False)])
def test_a_check_driven_on_turns_that_slip_arrives_when_the_camera_measures_them(
    driven_to_kitchen, compass_deg, arrives
):
    """A robot in office_b checks office_b by its route into the kitchen; its base turns 20 %
    too far every time. Steered on the turns it was told, the route ends off the kitchen's
    place; with each turn measured by the views before and after it, the route ends there."""
    sim = SimulatedRobot.kidnapped(make_world("building"), "office_b", seed=4, camera=CAMERA)
    params = ActiveParams(routes=RouteCheckParams(compass_min_turn_deg=compass_deg))
    result = localize_actively(
        Localizer(load_map(driven_to_kitchen)), SlippingRobot(sim, 0.2), params=params
    )
    first = result.checks[0]
    assert first.room == "office_b" and first.started
    assert first.confirmed is arrives


def odds(belief, room: str, other: str) -> float:
    probability = belief.as_dict()
    return probability[room] / probability[other]


def test_twins_whose_routes_all_end_in_the_hall_are_not_made_sure_by_them(driven):
    """Every route out of either office ends in the corridor both open onto: a check driven
    from the other office ends there too, and where the corridor looks alike at both doors it
    arrives. The checks leave the robot likelier in its office, not sure (36 : 1 when they
    counted as routes beyond)."""
    robot, result = kidnapped_and_localized(driven[0], "office_a", 5)
    assert result.checks
    assert result.final.top[0] == "office_a" == robot.true_room()
    assert result.final.state is LocalizationState.AMBIGUOUS


def test_a_check_that_cannot_start_brings_the_robot_back_to_where_it_stood(driven):
    """A robot in office_a whose homing to office_b's places drives off and gives up: it goes
    back to the place it stood at, not left where the homing gave up."""
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=5, camera=CAMERA)
    localizer = Localizer(load_map(driven[0]))
    calls: list[int] = []

    def home(place_id: int) -> HomingResult:
        calls.append(place_id)
        goal = localizer.map.fingerprint(place_id)
        if localizer.map.place(place_id).room == "office_b":
            moved = robot.move(math.pi / 2, 0.8)
            return HomingResult(False, 1, abs(moved.moved_m), "max_steps", goal)
        return drive_home(robot, goal, localizer.extract, ActiveParams().homing)

    result = localize_actively(localizer, robot, home=home)
    starts = [check.start for check in result.checks if check.room == "office_b"]
    assert starts, "office_b is checked"
    for start in starts:
        at = calls.index(start)
        assert at > 0 and calls[at + 1] == calls[at - 1]  # back where it stood
    assert robot.true_room() == "office_a"


def test_of_twins_with_routes_beyond_only_the_one_with_the_shorter_takes_it(driven_to_kitchen):
    """office_b's way on to the kitchen is shorter than office_a's: office_b is checked by it,
    office_a by its short route into the corridor, and on from the corridor's place, once
    there, to the kitchen (a long route drifts more; homing to the corridor's place
    re-anchors the drive)."""
    loaded = load_map(driven_to_kitchen)
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=5, camera=CAMERA)
    result = localize_actively(Localizer(loaded), robot)
    legs = {
        check.room: (check.via and loaded.place(check.via).room, loaded.place(check.end).room)
        for check in result.checks
    }
    assert legs == {"office_a": ("corridor", "kitchen"), "office_b": (None, "kitchen")}


def test_a_twin_is_checked_once_its_rival_took_the_route_beyond_before_less_likely_rooms(
    driven_to_kitchen,
):
    """office_b's route beyond told for the pair and missed: office_a, now likeliest, is
    checked next (by its short route into the corridor), not the corridor seen on the way
    (world seed 103's building, one place per room: a robot in office_a checked the corridor
    instead, and ended ambiguous at the drive limit)."""
    loaded = load_map(driven_to_kitchen)
    localizer = Localizer(loaded)
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=5, camera=CAMERA)
    look = localizer.observe(robot.capture().image)
    rooms = loaded.rooms
    p = {"office_a": 0.745, "office_b": 0.166, "corridor": 0.089}
    belief = RoomBelief.from_probabilities(rooms, np.array([p.get(r, 0.0) for r in rooms]))
    office_b = {place.id for place in loaded.places if place.room == "office_b"}
    params = RouteCheckParams()
    first = route_to_check(localizer, belief, look, set(), {}, params)
    assert first is not None and first[0].room == "office_b"
    after = route_to_check(localizer, belief, look, office_b, {"office_b": 1}, params)
    assert after is not None and after[0].room == "office_a"


def test_a_check_into_a_hall_that_repeats_is_told_by_the_drive_on_beyond_it(driven_to_kitchen):
    """A robot in office_b, whose homing to office_b's places goes nowhere, checks office_a by
    its route into the corridor. In a corridor that repeats, homing to the corridor's place
    arrives at once wherever the route ended (here: it stops there), an office's offset along;
    the drive on from there to the kitchen, re-anchored at the corridor's place, misses the
    kitchen, and office_a is not confirmed."""
    loaded = load_map(driven_to_kitchen)
    localizer = Localizer(loaded)
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_b", seed=5, camera=CAMERA)

    def home(place_id: int) -> HomingResult:
        goal, room = loaded.fingerprint(place_id), loaded.place(place_id).room
        if room == "office_b":
            return HomingResult(False, 0, 0.0, "converged", goal)
        if room == "corridor":  # it repeats: the view where the route ended is the place's
            return HomingResult(True, 0, 0.0, "arrived", localizer.extract(robot.capture().image))
        return drive_home(robot, goal, localizer.extract, ActiveParams().homing)

    result = localize_actively(localizer, robot, home=home)
    checks = [check for check in result.checks if check.room == "office_a" and check.started]
    assert checks and all(check.via is not None for check in checks)
    assert not any(check.confirmed for check in checks)
    assert not (
        result.final.top[0] == "office_a" and result.final.state is LocalizationState.LOCALIZED
    )


class _OfficeACheck:
    """A robot in office_a about to check office_a by its route into the corridor (the
    ``driven`` map, or another recorded on one drive; ``unknown_twins``: loaded as if the
    calibration had not paired the offices), office_b its rival, after one look; the test fakes
    the homings, and
    :meth:`carry` is a perfect one (the robot put at the place's true pose)."""

    def __init__(self, driven, unknown_twins: bool = False) -> None:
        db, recorded = driven
        self.truth = {place.place_id: place.true_pose for place in recorded}
        self.loaded = twins_unknown(db) if unknown_twins else load_map(db)
        self.localizer = Localizer(self.loaded)
        world = make_world("building")
        self.robot = SimulatedRobot.kidnapped(world, "office_a", seed=0, camera=CAMERA)
        self.localizer.update(self.localizer.observe(self.robot.capture().image))
        self.before = self.localizer.belief()
        self.params = ActiveParams()
        self.start = next(
            p for p in self.loaded.places if p.room == "office_a" and p.id in self.loaded.legs
        )
        route = route_out(
            self.loaded.legs, self.loaded.places, self.start.id, {"office_a", "office_b"}, 20.0
        )
        assert route is not None and self.loaded.place(route.end).room == "corridor"
        self.route = route

    def view(self):
        return self.localizer.extract(self.robot.capture().image)

    def carry(self, place_id: int, late_m: float = 0.0) -> HomingResult:
        """Homing to ``place_id`` that arrives, ``late_m`` metres later than the way there."""
        here, pose = self.robot.true_pose, self.truth[place_id]
        self.robot.carry(pose)
        driven_m = math.dist((here.x_m, here.y_m), (pose.x_m, pose.y_m)) + late_m
        return HomingResult(True, 1, driven_m, "arrived", self.view())

    def run(self, home: Callable[[int], HomingResult]):
        """The check, and the place the robot homed to last."""
        params = self.params
        check, _, _, homed_to = check_route(
            self.localizer,
            self.robot,
            home,
            self.start,
            self.route,
            "office_b",
            params.routes,
            params.homing,
        )
        return check, homed_to


def _arriving_late(driven, rival_reached_at_once: bool) -> tuple[_OfficeACheck, Any, Any]:
    """The office_a check, the homing to the corridor's place arriving late (further than the
    odometry's drift allows), the rival's place reached at once or not: the case, the check
    and the place the robot homed to last."""
    case = _OfficeACheck(driven)

    def home(place_id: int) -> HomingResult:
        room = case.loaded.place(place_id).room
        if room == "office_b" and not rival_reached_at_once:
            return HomingResult(False, 1, 0.5, "converged", case.loaded.fingerprint(place_id))
        late_m = case.params.routes.route_slack_max_m + 1.0 if room == "corridor" else 0.0
        return case.carry(place_id, late_m)

    check, homed_to = case.run(home)
    return case, check, homed_to


def test_a_check_that_reached_its_end_late_goes_into_the_rival_by_a_recorded_route(driven):
    """At the route's end place, reached late, the robot still knows where it is (a room
    without a look-alike): a recorded route from there into the rival that reaches the rival's
    place at once puts the robot there, and multiplies the rival's odds by the route ratio."""
    case, check, homed_to = _arriving_late(driven, True)
    after = case.localizer.belief()
    assert (check.confirmed, check.back_room, check.afresh) == (False, "office_b", False)
    assert homed_to is not None and case.robot.true_room() == "office_b" == after.top[0]
    ratio = odds(after, "office_b", "office_a") / odds(case.before, "office_b", "office_a")
    params = RouteCheckParams()
    assert ratio == pytest.approx(params.route_hit_rate / params.route_false_rate)


def test_a_way_into_the_rival_that_does_not_arrive_starts_the_belief_afresh(driven):
    """The same check, but the rival's place is not reached: the robot is somewhere along the
    way back, and the belief starts afresh (the next look decides)."""
    case, check, homed_to = _arriving_late(driven, False)
    after = case.localizer.belief()
    assert (check.confirmed, check.back_room, check.afresh) == (False, None, True)
    assert homed_to is None
    assert after.top[1] == pytest.approx(1.0 / len(after.ranked()))  # uniform again


def test_a_way_back_that_held_tells_the_check_though_the_start_is_not_reached(driven):
    """A robot in office_a checks office_a by its route into the corridor and comes back
    through the views it took on the way out, but its last homing, to the start place's view,
    does not arrive: it stands at the first view it took, in the room it left, so the check
    tells about that room (office_a's odds multiplied by the check's ratio; not started
    afresh)."""
    case = _OfficeACheck(driven)
    homed: list[int] = []

    def home(place_id: int) -> HomingResult:
        homed.append(place_id)
        if place_id == case.start.id and homed.count(place_id) > 1:  # back: it does not arrive
            return HomingResult(False, 1, 0.1, "converged", case.view())
        return case.carry(place_id)  # at once, where the place was recorded

    check, homed_to = case.run(home)
    assert check.started and check.confirmed
    assert (check.back_room, check.afresh, homed_to) == ("office_a", False, None)
    assert case.robot.true_room() == "office_a"
    after = case.localizer.belief()
    ratio = odds(after, "office_a", "office_b") / odds(case.before, "office_a", "office_b")
    params = RouteCheckParams()  # into the corridor office_b opens onto too: the hall's rates
    assert ratio == pytest.approx(params.hall_route_hit_rate / params.hall_route_false_rate)


def test_a_missed_check_of_a_room_of_one_place_doubts_it_though_the_start_is_not_reached(
    one_place,
):
    """A room of one place and no known look-alike whose check misses is doubted (its looks may
    have been an unknown twin's) when the way back holds, whether or not the last homing, to
    the start place's view, arrives: later frames favour it no more than the next room."""
    case = _OfficeACheck(one_place, unknown_twins=True)
    assert case.localizer.alone("office_a")
    homed: list[int] = []

    def home(place_id: int) -> HomingResult:
        homed.append(place_id)
        if place_id == case.start.id and homed.count(place_id) == 1:
            return case.carry(place_id)  # the start: at once
        return HomingResult(False, 1, 0.1, "converged", case.view())  # the end, and back

    check, homed_to = case.run(home)
    assert check.started and not check.confirmed
    assert (check.back_room, homed_to) == ("office_a", None)
    assert case.localizer.doubted == {"office_a"}


class FoggedRobot(RobotWrapper):
    """The simulated robot, whose camera sees a blank wall while ``fogged``, except in the
    rooms ``clear_in``."""

    def __init__(self, robot: SimulatedRobot, clear_in: tuple[str, ...] = ()) -> None:
        super().__init__(robot)
        self.fogged = False
        self.clear_in = clear_in

    def capture(self) -> Capture:
        captured = self.robot.capture()
        if not self.fogged or self.robot.true_room() in self.clear_in:
            return captured
        return replace(captured, image=np.full_like(captured.image, 200))


def test_a_way_back_whose_marks_were_not_reached_tells_nothing_and_starts_afresh(
    driven_to_kitchen,
):
    """Out of the offices the robot sees nothing but while it homes to a place: its homings to
    the views it took on the way out do not arrive, so where it ends, even at once at a place
    of the room, may be the look-alike's. The check is not folded in: the belief starts
    afresh."""
    loaded = load_map(driven_to_kitchen)
    localizer = Localizer(loaded)
    robot = FoggedRobot(
        SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=5, camera=CAMERA)
    )

    def home(place_id: int) -> HomingResult:
        robot.fogged = False
        homed = drive_home(
            robot, loaded.fingerprint(place_id), localizer.extract, ActiveParams().homing
        )
        robot.fogged = loaded.place(place_id).room not in ("office_a", "office_b")
        return homed

    result = localize_actively(localizer, robot, home=home)
    started = [check for check in result.checks if check.started]
    assert started
    assert all(check.afresh and check.back_room is None for check in started)


def test_a_way_back_that_reached_only_its_last_marks_tells_nothing_and_starts_afresh(
    driven_to_kitchen,
):
    """As above, but the fog clears in the offices: of the views the robot took on the way
    out, it reaches only those in an office, the last it homes to among them. Most of its way
    back was driven blind, and an office it reaches at once may be the look-alike of the one it
    left (the views there repeat). The check is not folded in: the belief starts afresh."""
    loaded = load_map(driven_to_kitchen)
    localizer = Localizer(loaded)
    offices = ("office_a", "office_b")
    sim = SimulatedRobot.kidnapped(make_world("building"), "office_a", seed=5, camera=CAMERA)
    robot = FoggedRobot(sim, clear_in=offices)

    def home(place_id: int) -> HomingResult:
        robot.fogged = False
        homed = drive_home(
            robot, loaded.fingerprint(place_id), localizer.extract, ActiveParams().homing
        )
        robot.fogged = loaded.place(place_id).room not in offices
        return homed

    result = localize_actively(localizer, robot, home=home)
    started = [check for check in result.checks if check.started]
    assert started
    assert all(check.afresh and check.back_room is None for check in started)


@pytest.fixture(scope="module")
def twin_wings(tmp_path_factory):
    """``house``'s hall and its two identical wings (bedroom_a and bathroom_a, bedroom_b and
    bathroom_b, 6.6 m apart), one place each, recorded on one drive in that order (seed 3):
    the calibration pairs the bedrooms, not the bathrooms."""
    db = tmp_path_factory.mktemp("twin_wings") / "map.db"
    rooms = ("hall", "bedroom_a", "bathroom_a", "bedroom_b", "bathroom_b")
    record_map(make_world("house"), 1, 3, db, rooms=rooms, camera=CAMERA, drive=True)
    return db


def test_a_route_into_a_room_of_one_place_does_not_settle_what_a_copied_wing_would_repeat(
    twin_wings,
):
    """A robot in bedroom_b checks bedroom_a by its route into bathroom_a: driven from
    bedroom_b, it ends in bathroom_b, the bathroom_a the map has a place of seen at the same
    spot of an identical room, and arrives at once; back through its own views, the robot
    stands where the map has bedroom_a's place, by an odometry fixed a wing's offset off. The
    map cannot tell from one place that bathroom_a has a twin, so the arrival is one route's
    evidence, not a retraced route's (sure of bedroom_a, 0.985, when it counted as one); the
    robot is never sure of bedroom_a, after that check nor after the checks that follow."""
    loaded = load_map(twin_wings)
    assert loaded.likelihood is not None
    assert loaded.likelihood.lookalikes == (("bedroom_a", "bedroom_b"),)
    robot = SimulatedRobot.kidnapped(make_world("house"), "bedroom_b", seed=0, camera=CAMERA)
    result = localize_actively(Localizer(loaded), robot)
    fooled = [c for c in result.checks if c.room == "bedroom_a" and c.confirmed]
    assert fooled and loaded.place(fooled[0].end).room == "bathroom_a"
    assert robot.true_room() == "bedroom_b"
    beliefs = [visit.belief for visit in result.visits] + [result.final]
    assert not any(
        b.state is LocalizationState.LOCALIZED and b.top[0] == "bedroom_a" for b in beliefs
    )
    assert result.final.top[0] == "bedroom_b"


def test_a_room_sure_by_its_odds_but_seen_on_little_of_the_horizon_is_settled_from_its_place(
    twin_wings,
):
    """A robot in a corner of bathroom_b, the odds for bathroom_b strong (as after its route
    check): the room's one place covers a third of the horizon from there, as from a doorway,
    so the belief waits; homed to that place, the robot sees it all round."""
    localizer = Localizer(load_map(twin_wings))
    robot = SimulatedRobot.kidnapped(make_world("house"), "bathroom_b", seed=2, camera=CAMERA)
    localizer.update(localizer.observe(robot.capture().image))
    localizer.update_rooms({"bathroom_b": 1000.0})
    assert localizer.belief().state is LocalizationState.AMBIGUOUS
    assert localizer.unseen_room() == "bathroom_b"
    [place] = [p for p in localizer.map.places if p.room == "bathroom_b"]
    homed = drive_home(robot, localizer.map.fingerprint(place.id), localizer.extract)
    assert homed.arrived
    localizer.update(localizer.observe(robot.capture().image))
    assert localizer.unseen_room() is None
    assert localizer.belief().state is LocalizationState.LOCALIZED
    assert localizer.belief().top[0] == "bathroom_b" == robot.true_room()


def test_a_loop_held_back_only_by_a_one_place_room_seen_from_afar_ends_with_a_look_from_it(
    twin_wings,
):
    """A robot in bathroom_b: its drives leave the odds for bathroom_b well past the one-place
    ratio, but it stands where bathroom_b's one place covers little of its horizon. Rather
    than end ambiguous with no telling place left, it homes to that place to look from there
    (here that homing ends short of it, and the belief stays ambiguous, right). Seed 0 was
    this case until homing took the planar pose (session 46), seed 5 until a frame on a place
    of the room counted as seeing it (session 47): both now end localized sooner."""
    loaded = load_map(twin_wings)
    robot = SimulatedRobot.kidnapped(make_world("house"), "bathroom_b", seed=34, camera=CAMERA)
    result = localize_actively(Localizer(loaded), robot)
    [place] = [p.id for p in loaded.places if p.room == "bathroom_b"]
    before, last = result.visits[-2].belief, result.visits[-1]
    assert before.state is LocalizationState.AMBIGUOUS and before.top[0] == "bathroom_b"
    assert top_two_ratio(np.asarray(before.probabilities)) >= StateThresholds().one_place_ratio
    assert last.place_id == place
    assert result.final.top[0] == "bathroom_b" == robot.true_room()


def test_twins_whose_checks_both_arrive_are_checked_by_routes_that_end_elsewhere(twin_wings):
    """A robot in bedroom_a: each bedroom's route leads into the bathroom beside it, a copy of
    the other wing's that the map does not know as one, and both checks arrive. Those routes
    end alike and tell nothing; the robot checks again by routes into the hall, whose view
    does not repeat where the other wing's route would end (before, it stopped there, at
    0.5)."""
    loaded = load_map(twin_wings)
    robot = SimulatedRobot.kidnapped(make_world("house"), "bedroom_a", seed=2, camera=CAMERA)
    result = localize_actively(Localizer(loaded), robot)
    ends = [(c.room, loaded.place(c.first_end).room, c.confirmed) for c in result.checks]
    assert ends[:2] == [("bedroom_a", "bathroom_a", True), ("bedroom_b", "bathroom_b", True)]
    assert {room for _, room, _ in ends[2:]} == {"hall"}
    assert result.final.top[0] == "bedroom_a" == robot.true_room()
    assert result.final.state is LocalizationState.LOCALIZED
