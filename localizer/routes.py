"""Recorded routes between places, and driving one back by odometry.

A place recorded on a drive keeps its :class:`~mapdb.records.Leg`: the place recorded before it
and the odometry positions driven between. The legs join places into a graph; along a path of
legs every pose is in one frame, the odometry frame of the drive that recorded them (the
*drive frame*). A :class:`Route` is such a path, from a start place to an end place, as the
positions to drive through. Look-alike rooms that no place tells apart are told apart this way
(:mod:`localizer.active`): a robot that homed to a place of one twin drives that twin's route
out of the room; if it is in the other twin, the same drive ends somewhere else.

:func:`leg_graph`, :func:`route_out` and :func:`route_into` are pure; :func:`drive_route`
moves a :class:`~localizer.robot_protocol.Robot` along a route, steering on its odometry.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import cast

import networkx as nx

from homing.bearings import wrap_angle_rad
from localizer.robot_protocol import Pose2D, Robot
from mapdb.records import Place

ROUTE_MAX_M = 15.0
"""The longest route the active localizer drives to check a room (metres)."""


@dataclass(frozen=True)
class Route:
    """A recorded path from place ``start`` to place ``end``: the positions to drive through
    (``waypoints_xy_m``, drive frame, metres; the last is ``end``'s position) and its length
    from ``start``'s position (metres)."""

    start: int
    end: int
    start_xy_m: tuple[float, float]
    waypoints_xy_m: tuple[tuple[float, float], ...]
    length_m: float


def _length_m(points: Sequence[tuple[float, float]]) -> float:
    return sum(math.dist(a, b) for a, b in itertools.pairwise(points))


def leg_graph(places: Sequence[Place]) -> nx.Graph:
    """The places joined by their legs: an undirected graph on place ids whose edges carry
    ``points`` (the leg's positions from the lower id to the higher, ends included, drive
    frame) and ``length_m``. Places without a leg (nor one from them) are not in it; a leg
    from a place that has no position, or that is not among ``places``, is left out."""
    by_id = {place.id: place for place in places}
    graph: nx.Graph[int] = nx.Graph()
    for place in places:
        leg = place.leg
        origin = by_id.get(leg.from_place) if leg is not None else None
        if leg is None or origin is None or origin.xy_m is None or place.xy_m is None:
            continue
        points = (origin.xy_m, *leg.via_xy_m, place.xy_m)
        if origin.id > place.id:
            points = tuple(reversed(points))
        low, high = sorted((origin.id, place.id))
        graph.add_edge(low, high, points=points, length_m=_length_m(points))
    return graph


def _path_points(graph: nx.Graph, path: Sequence[int]) -> list[tuple[float, float]]:
    """The positions along ``path`` (place ids), ends included."""
    points: list[tuple[float, float]] = []
    for a, b in itertools.pairwise(path):
        leg = graph.edges[a, b]["points"]
        leg = leg if a < b else tuple(reversed(leg))
        points.extend(leg if not points else leg[1:])
    return points


def route_out(
    graph: nx.Graph,
    places: Sequence[Place],
    start: int,
    leave: Collection[str],
    max_length_m: float,
) -> Route | None:
    """The shortest recorded route from place ``start`` to a place of a room not in
    ``leave`` (the rooms to get out of), at most ``max_length_m`` long; None if there is
    none (``start`` has no leg, or every route is longer)."""
    return _shortest_route(graph, places, start, lambda room: room not in leave, max_length_m)


def route_into(
    graph: nx.Graph,
    places: Sequence[Place],
    start: int,
    rooms: Collection[str],
    max_length_m: float,
) -> Route | None:
    """The shortest recorded route from place ``start`` to another place of one of
    ``rooms``, at most ``max_length_m`` long; None if there is none."""
    return _shortest_route(graph, places, start, lambda room: room in rooms, max_length_m)


def _shortest_route(
    graph: nx.Graph,
    places: Sequence[Place],
    start: int,
    wanted: Callable[[str], bool],
    max_length_m: float,
) -> Route | None:
    """The shortest route from place ``start`` to another place whose room is ``wanted``."""
    if start not in graph:
        return None
    room_of = {place.id: place.room for place in places}
    found = nx.single_source_dijkstra(graph, start, cutoff=max_length_m, weight="length_m")
    lengths, paths = cast(tuple[dict[int, float], dict[int, list[int]]], found)
    ends = [node for node in lengths if node != start and node in room_of and wanted(room_of[node])]
    if not ends:
        return None
    end = min(ends, key=lambda node: (lengths[node], node))
    points = _path_points(graph, paths[end])
    return Route(start, end, points[0], tuple(points[1:]), float(lengths[end]))


def shared_rooms(
    doors: Mapping[str, frozenset[str]], room: str, twins: Collection[str]
) -> set[str]:
    """The rooms a door (``doors``: each room's neighbours) joins both to ``room`` and to one
    of its look-alikes ``twins``: a hall both twins open onto. A route from ``room`` that
    ends there, driven from the twin, ends there too, a twin's offset along it, and where that
    hall repeats (doors at the same spacing) its view there is the end place's: world seed
    27's house, two places per room, whose bedrooms' routes ended in the hall, arrived from the
    other bedroom in 9 of 10 checks, and the building, one place per room, whose office_a's
    route ended in the corridor, in 4 of 6; the house's routes that ended in a room beyond
    (the living room) in 1 of 10."""
    return {r for r in doors.get(room, ()) if any(r in doors.get(t, ()) for t in twins)}


def rooms_with_routes_beyond(
    places: Sequence[Place],
    lookalikes: Mapping[str, frozenset[str]],
    doors: Mapping[str, frozenset[str]],
    max_length_m: float,
) -> set[str]:
    """The rooms with look-alikes (``lookalikes``: each room's) that have a place with a
    recorded route (at most ``max_length_m``) on beyond the hall they share with them
    (:func:`shared_rooms`; ``doors``: each room's neighbours) to a room without look-alikes."""
    paired = {room for room, twins in lookalikes.items() if twins}
    return {
        room
        for room in paired
        if room
        in rooms_with_routes_out(
            places, paired | shared_rooms(doors, room, lookalikes[room]), max_length_m
        )
    }


def rooms_with_routes_out(
    places: Sequence[Place], leave: Collection[str], max_length_m: float
) -> set[str]:
    """The rooms with a place that has a recorded route (at most ``max_length_m``) to a room
    neither in ``leave`` nor the place's own."""
    graph = leg_graph(places)
    return {
        place.room
        for place in places
        if route_out(graph, places, place.id, {*leave, place.room}, max_length_m) is not None
    }


@dataclass(frozen=True)
class RouteDrive:
    """How a drive along a route went: the moves made, the odometric distance (metres), how
    many moves contact stopped, and the robot's pose in the drive frame at the end (as its
    odometry has it)."""

    moves: int
    distance_m: float
    bumps: int
    end: Pose2D


class DriveFrame:
    """The robot's pose in a drive frame from its odometry: fixed by one moment at which the
    robot's pose in the drive frame was known (``at``) and its odometry then."""

    def __init__(self, at: Pose2D, odometry: Pose2D) -> None:
        self.at, self.odometry = at, odometry

    def pose(self, odometry: Pose2D) -> Pose2D:
        """Where ``odometry`` (a later odometry pose) is in the drive frame."""
        dx, dy = odometry.x_m - self.odometry.x_m, odometry.y_m - self.odometry.y_m
        turn = self.at.heading_rad - self.odometry.heading_rad
        cos, sin = math.cos(turn), math.sin(turn)
        heading = float(wrap_angle_rad(odometry.heading_rad + turn))
        return Pose2D(self.at.x_m + cos * dx - sin * dy, self.at.y_m + sin * dx + cos * dy, heading)


SLIDE_DEG = (25.0, -25.0, 50.0, -50.0)
"""After contact, the headings (degrees off the waypoint's bearing) tried in turn to slide
along the obstacle before aiming at the waypoint again: odometry drifts a few centimetres per
metre and a few degrees per turn, and a recorded route goes through doors with a hand's
breadth to spare; a door frame grazed is passed this way."""
SLIDE_BACK_M = 0.1
SLIDE_M = 0.3
ARRIVED_M = 0.05


def drive_route(
    robot: Robot,
    route: Route,
    frame: DriveFrame,
    at_waypoint: Callable[[int], None] | None = None,
) -> RouteDrive:
    """Drive ``robot`` through the route's waypoints, each a turn toward it and a straight
    drive, steering on the pose ``frame`` gives its odometry. After contact the robot backs
    off and slides past (:data:`SLIDE_DEG`), then aims at the waypoint again; when every slide
    is tried it goes on to the next waypoint (the robot may be in a look-alike room where the
    route does not fit; where it ends says so). ``at_waypoint(i)`` is called when the robot is
    done with waypoint ``i`` (to take a view there, say)."""
    moves, distance_m, bumps = 0, 0.0, 0
    odometry = robot.odometry()

    def move(turn_rad: float, forward_m: float) -> bool:
        nonlocal moves, distance_m, bumps, odometry
        moved = robot.move(turn_rad, forward_m)
        moves += 1
        distance_m += abs(moved.moved_m)
        bumps += bool(moved.bumped)
        odometry = robot.odometry()
        return bool(moved.bumped)

    for index, (x_m, y_m) in enumerate(route.waypoints_xy_m):
        for slide_deg in (None, *SLIDE_DEG):
            here = frame.pose(robot.odometry())
            dx, dy = x_m - here.x_m, y_m - here.y_m
            if math.hypot(dx, dy) < ARRIVED_M:
                break
            bearing_rad = math.atan2(dy, dx)
            if slide_deg is not None:  # the last move bumped: back off, slide, aim again
                move(0.0, -SLIDE_BACK_M)
                here = frame.pose(odometry)
                slide_rad = bearing_rad + math.radians(slide_deg)
                move(float(wrap_angle_rad(slide_rad - here.heading_rad)), SLIDE_M)
                here = frame.pose(odometry)
                dx, dy = x_m - here.x_m, y_m - here.y_m
                bearing_rad = math.atan2(dy, dx)
            turn_rad = float(wrap_angle_rad(bearing_rad - here.heading_rad))
            if not move(turn_rad, math.hypot(dx, dy)):
                break
        if at_waypoint is not None:
            at_waypoint(index)
    return RouteDrive(moves, distance_m, bumps, frame.pose(odometry))


def route_through(
    here_xy_m: tuple[float, float], points_xy_m: Sequence[tuple[float, float]]
) -> Route:
    """A route through ``points_xy_m`` from ``here_xy_m`` (a drive frame's metres) that no
    recording made: a way back, say (``start`` and ``end`` 0: no place)."""
    points = (here_xy_m, *points_xy_m)
    return Route(0, 0, here_xy_m, tuple(points_xy_m), _length_m(points))


ODOMETRY = DriveFrame(Pose2D(0.0, 0.0, 0.0), Pose2D(0.0, 0.0, 0.0))
"""The drive frame that is the odometry frame itself."""
