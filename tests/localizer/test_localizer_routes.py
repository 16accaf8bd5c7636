"""Recorded routes: places joined by the legs they were recorded on, the shortest way out of a
room, and driving a route (and back) by odometry."""

from __future__ import annotations

import math

import networkx as nx
import pytest
from hypothesis import given
from hypothesis import strategies as st

from localizer.robot_protocol import MoveResult, Pose2D
from localizer.routes import (
    JUNCTION_M,
    ODOMETRY,
    DriveFrame,
    Route,
    drive_route,
    leg_graph,
    route_into,
    route_out,
    route_through,
    way_in_rad,
)
from mapdb.records import Leg, Place

# office place 1 -> office place 2 -> (through the door) corridor place 3 -> kitchen place 4
PLACES = (
    Place(1, "office", 0.0, 0.0, 0.0),
    Place(2, "office", 1.0, 0.0, 90.0, leg=Leg(1)),
    Place(3, "corridor", 1.0, 3.0, 90.0, leg=Leg(2, ((1.0, 1.0), (1.5, 2.0)))),
    Place(4, "kitchen", 5.0, 3.0, 0.0, leg=Leg(3)),
    Place(5, "office", None, None, None),  # carried there: no leg
)


def test_places_are_joined_by_the_legs_they_were_recorded_on() -> None:
    graph = leg_graph(PLACES, junction_m=0.0)
    assert sorted(node for node in graph if isinstance(node, int)) == [1, 2, 3, 4]
    assert nx.shortest_path_length(graph, 1, 2, weight="length_m") == pytest.approx(1.0)
    leg_m = 1.0 + 2 * math.hypot(0.5, 1.0)  # through (1, 1) and (1.5, 2)
    assert nx.shortest_path_length(graph, 2, 3, weight="length_m") == pytest.approx(leg_m)
    assert graph.nodes[3]["xy"] == (1.0, 3.0)
    assert 5 not in graph


def test_a_leg_from_a_place_without_a_position_joins_nothing() -> None:
    places = (Place(1, "office"), Place(2, "office", 1.0, 0.0, 0.0, leg=Leg(1)))
    assert leg_graph(places).number_of_edges() == 0


def test_the_way_out_is_the_shortest_route_to_another_room() -> None:
    route = route_out(leg_graph(PLACES, junction_m=0.0), PLACES, 1, {"office"}, max_length_m=20.0)
    assert route is not None
    assert (route.start, route.end) == (1, 3)
    assert route.start_xy_m == (0.0, 0.0)
    assert route.waypoints_xy_m == ((1.0, 0.0), (1.0, 1.0), (1.5, 2.0), (1.0, 3.0))
    assert route.length_m == pytest.approx(1.0 + 1.0 + math.hypot(0.5, 1.0) * 2)


def test_the_way_out_leaves_every_room_named() -> None:
    route = route_out(leg_graph(PLACES), PLACES, 1, {"office", "corridor"}, max_length_m=20.0)
    assert route is not None and route.end == 4


def test_no_route_out_for_a_place_without_legs_or_beyond_the_longest() -> None:
    graph = leg_graph(PLACES)
    assert route_out(graph, PLACES, 5, {"office"}, max_length_m=20.0) is None
    assert route_out(graph, PLACES, 1, {"office"}, max_length_m=2.0) is None


def test_the_way_into_a_room_is_the_shortest_route_to_one_of_its_places() -> None:
    route = route_into(leg_graph(PLACES), PLACES, 4, {"office"}, max_length_m=20.0)
    assert route is not None and (route.start, route.end) == (4, 2)  # place 2 is nearer than 1
    assert route.waypoints_xy_m[-1] == (1.0, 0.0)
    assert route_into(leg_graph(PLACES), PLACES, 4, {"office"}, max_length_m=5.0) is None


def test_the_way_into_its_own_room_leads_to_another_place_of_it() -> None:
    route = route_into(leg_graph(PLACES), PLACES, 1, {"office"}, max_length_m=20.0)
    assert route is not None and route.end == 2


# A drive: hall place 1, into the office (place 2) and back out through the hall, past place
# 1, to the kitchen (place 3). The legs alone lead from the kitchen to the hall through the
# office; where the last leg passes place 1 they join.
DRIVE = (
    Place(1, "hall", 0.0, 0.0, 0.0),
    Place(2, "office", 0.0, 3.0, 90.0, leg=Leg(1, ((0.0, 1.5),))),
    Place(3, "kitchen", 5.0, 0.0, 0.0, leg=Leg(2, ((0.0, 1.5), (0.0, 0.2)))),
)


def test_legs_of_one_drive_join_where_they_pass_each_other() -> None:
    route = route_into(leg_graph(DRIVE), DRIVE, 3, {"hall"}, max_length_m=20.0)
    assert route is not None and route.end == 1
    assert route.length_m < 5.0 + JUNCTION_M  # through the office: 10.8 m
    assert max(y for _, y in route.waypoints_xy_m) < 0.5  # not through the office


def test_a_route_stops_only_where_it_turns() -> None:
    """``toploc map record`` keeps a position every 0.1 m: a route through all of them would
    stop and look at each."""
    trail = tuple((0.1 * k, 0.0) for k in range(1, 30)) + tuple((3.0, 0.1 * k) for k in range(20))
    places = (
        Place(1, "office", 0.0, 0.0, 0.0),
        Place(2, "corridor", 3.0, 2.0, 90.0, leg=Leg(1, trail)),
    )
    route = route_out(leg_graph(places, junction_m=0.0), places, 1, {"office"}, max_length_m=20.0)
    assert route is not None
    assert route.waypoints_xy_m == ((3.0, 0.0), (3.0, 2.0))
    assert route.length_m == pytest.approx(5.0)


def test_legs_of_two_drives_do_not_join() -> None:
    """Another drive's odometry is another frame: near in numbers is not near on the floor."""
    other = Place(5, "kitchen", 5.0, 0.0, 0.0, leg=Leg(4, ((0.0, 1.5), (0.0, 0.2))))
    places = (*DRIVE[:2], Place(4, "office", 0.0, 3.0, 90.0), other)
    graph = leg_graph(places)
    assert not nx.has_path(graph, 5, 1)


def test_a_junction_that_saves_little_is_no_shortcut() -> None:
    graph = leg_graph(PLACES)
    assert not any(shortcut for _, _, shortcut in graph.edges(data="shortcut"))


poses = st.builds(
    Pose2D,
    st.floats(-50, 50),
    st.floats(-50, 50),
    st.floats(-math.pi, math.pi),
)


@given(at=poses, anchor=poses, step=poses)
def test_a_drive_frame_moves_odometry_rigidly(at: Pose2D, anchor: Pose2D, step: Pose2D) -> None:
    frame = DriveFrame(at, anchor)
    start = frame.pose(anchor)
    assert (start.x_m, start.y_m) == pytest.approx((at.x_m, at.y_m), abs=1e-9)
    later = frame.pose(step)
    odometry_m = math.hypot(step.x_m - anchor.x_m, step.y_m - anchor.y_m)
    driven_m = math.hypot(later.x_m - at.x_m, later.y_m - at.y_m)
    assert driven_m == pytest.approx(odometry_m, abs=1e-6)
    turn = math.remainder(later.heading_rad - at.heading_rad, 2 * math.pi)
    odometry_turn = math.remainder(step.heading_rad - anchor.heading_rad, 2 * math.pi)
    assert math.remainder(turn - odometry_turn, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)


class PlanRobot:
    """Moves exactly as told (its odometry is the truth), except that contact stops a move
    into the wall y = ``wall_y_m`` anywhere but in its door (|x| < ``door_half_m``)."""

    def __init__(self, pose: Pose2D, wall_y_m: float = math.inf, door_half_m: float = 0.3):
        self.pose, self.wall_y_m, self.door_half_m = pose, wall_y_m, door_half_m
        self.bumps = 0

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        heading = self.pose.heading_rad + turn_rad
        x, y = self.pose.x_m, self.pose.y_m
        steps = max(1, math.ceil(abs(forward_m) / 0.01))
        moved, bumped = 0.0, False
        for i in range(1, steps + 1):
            s = forward_m * i / steps
            nx, ny = x + s * math.cos(heading), y + s * math.sin(heading)
            crosses = (y < self.wall_y_m) != (ny < self.wall_y_m)
            if crosses and abs(nx) >= self.door_half_m:
                bumped = True
                break
            moved = s
        self.bumps += bumped
        self.pose = Pose2D(x + moved * math.cos(heading), y + moved * math.sin(heading), heading)
        return MoveResult(turn_rad, moved, bumped)

    def odometry(self) -> Pose2D:
        return self.pose

    def capture(self):  # pragma: no cover - routes do not look
        raise AssertionError("a route is driven blind")

    def stop(self) -> None:
        """Nothing to stop."""


def test_a_route_is_driven_through_its_waypoints_on_the_odometry() -> None:
    robot = PlanRobot(Pose2D(0.0, 0.0, 2.0))
    route = Route(1, 3, (0.0, 0.0), ((1.0, 0.0), (1.0, 3.0)), 4.0)
    drive = drive_route(robot, route, ODOMETRY)
    assert (robot.pose.x_m, robot.pose.y_m) == pytest.approx((1.0, 3.0))
    assert drive.distance_m == pytest.approx(4.0)
    assert drive.bumps == 0


def test_a_route_is_steered_in_the_frame_of_its_start_place() -> None:
    robot = PlanRobot(Pose2D(10.0, 5.0, 0.0))  # its odometry knows nothing of the route's frame
    frame = DriveFrame(Pose2D(0.0, 0.0, math.pi / 2), robot.odometry())  # at (0, 0), facing +y
    drive_route(robot, Route(1, 2, (0.0, 0.0), ((0.0, 2.0),), 2.0), frame)
    assert (robot.pose.x_m, robot.pose.y_m) == pytest.approx((12.0, 5.0))  # straight ahead


def test_a_door_frame_grazed_is_slid_past() -> None:
    robot = PlanRobot(Pose2D(0.35, 0.0, 0.0), wall_y_m=1.0)  # really 5 cm beyond the door
    believed = DriveFrame(Pose2D(0.25, 0.0, 0.0), robot.odometry())  # the drift: 10 cm
    drive_route(robot, Route(1, 2, (0.25, 0.0), ((0.25, 2.0),), 2.0), believed)
    assert robot.bumps >= 1
    assert robot.pose.y_m == pytest.approx(2.0, abs=0.05)  # through the door


def test_a_route_says_when_the_robot_is_done_with_each_waypoint() -> None:
    robot = PlanRobot(Pose2D(0.0, 0.0, 0.0))
    reached: dict[int, tuple[float, float]] = {}

    def at_waypoint(i: int) -> None:
        reached[i] = (robot.pose.x_m, robot.pose.y_m)

    route = Route(1, 3, (0.0, 0.0), ((1.0, 0.0), (1.0, 3.0)), 4.0)
    drive_route(robot, route, ODOMETRY, at_waypoint)
    assert list(reached) == [0, 1]
    assert reached[0] == pytest.approx((1.0, 0.0)) and reached[1] == pytest.approx((1.0, 3.0))


def test_a_way_back_that_no_recording_made_runs_through_its_points() -> None:
    back = route_through((1.0, 3.0), [(1.0, 0.0), (0.0, 0.0)])
    assert back.waypoints_xy_m == ((1.0, 0.0), (0.0, 0.0))
    assert back.length_m == pytest.approx(4.0)


HALL = Place(10, "hall", -2.0, 0.0, 0.0)
"""A place in the hall, 2 m before a door on the line x = 0 into the room at x > 0."""


def _entered(x_m: float, y_m: float, via: tuple[tuple[float, float], ...]) -> Place:
    return Place(11, "room", x_m, y_m, 0.0, leg=Leg(HALL.id, via))


def test_the_way_in_is_the_drive_through_the_door_to_the_place() -> None:
    place = _entered(1.0, 0.0, ((-1.0, 0.0), (0.0, 0.0), (0.5, 0.0)))
    assert way_in_rad(place, HALL) == pytest.approx(0.0)


def test_the_way_in_points_into_the_room_from_a_place_turned_back_towards_the_door() -> None:
    # through the door to 0.6 m in, then a turn and 0.5 m back, 0.15 m from the door line
    back_rad = math.radians(160.0)
    x_m, y_m = 0.6 + 0.5 * math.cos(back_rad), 0.5 * math.sin(back_rad)
    place = _entered(x_m, y_m, ((-0.6, 0.0), (0.6, 0.0)))
    bearing_rad = way_in_rad(place, HALL)
    assert bearing_rad is not None and math.cos(bearing_rad) > 0.5  # into the room, x > 0


@given(
    st.floats(-math.pi, math.pi),
    st.floats(0.7, 5.0),
    st.floats(-10.0, 10.0),
    st.floats(-10.0, 10.0),
)
def test_a_straight_leg_goes_in_along_its_own_heading(
    heading_rad: float, length_m: float, x0_m: float, y0_m: float
) -> None:
    ux, uy = math.cos(heading_rad), math.sin(heading_rad)
    start = Place(10, "hall", x0_m, y0_m, 0.0)
    via = tuple((x0_m + ux * k * 0.1, y0_m + uy * k * 0.1) for k in range(1, int(length_m * 10)))
    place = Place(11, "room", x0_m + ux * length_m, y0_m + uy * length_m, 0.0, leg=Leg(10, via))
    bearing_rad = way_in_rad(place, start)
    assert bearing_rad is not None
    assert math.remainder(bearing_rad - heading_rad, math.tau) == pytest.approx(0.0, abs=1e-6)


def test_no_way_in_for_a_leg_within_its_room_or_a_place_without_pose_or_leg() -> None:
    via = ((-1.0, 0.0), (0.0, 0.0))
    assert way_in_rad(_entered(1.0, 0.0, via), Place(10, "room", -2.0, 0.0, 0.0)) is None
    assert way_in_rad(Place(11, "room", None, None, None, leg=Leg(10, via)), HALL) is None
    assert way_in_rad(Place(11, "room", 1.0, 0.0, 0.0), HALL) is None
    assert way_in_rad(_entered(1.0, 0.0, via), Place(9, "hall", -2.0, 0.0, 0.0)) is None
