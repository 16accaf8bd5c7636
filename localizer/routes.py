"""Recorded routes between places, and driving one back by odometry.

A place recorded on a drive keeps its :class:`~mapdb.records.Leg`: the place recorded before it
and the odometry positions driven between. The legs join places into a graph; along a path of
legs every pose is in one frame, the odometry frame of the drive that recorded them (the
*drive frame*). Legs of one drive that pass near each other (the drive crossed the hall again
on its way to the next room) join there too, so a route need not retrace the drive's detours
(:func:`leg_graph`). A :class:`Route` is such a path, from a start place to an end place, as
the positions to drive through. Look-alike rooms that no place tells apart are told apart this way
(:mod:`localizer.route_checks`): a robot that homed to a place of one twin drives that twin's route
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

import cv2
import networkx as nx
import numpy as np
from scipy.spatial import cKDTree

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


RoadNode = int | tuple[int, int]
"""A node of :func:`leg_graph`: a place id, or ``(place id, k)``, the ``k``-th point along the
leg the place was recorded on."""
JUNCTION_M = 0.3
"""Two legs of one drive join where they pass within this distance (metres, drive frame) of
each other. The simulated recording keeps 0.2 m from walls, so points on the two sides of a
wall are at least 0.4 m apart (a robot driven closer along both sides of a thin wall would get
a junction through it: a route through there bumps, slides and, in a check, misses); on a
drive of the house (world seed 31, two places per room) the legs
joined this way cut the routes from bedroom_b to the hall from 25 m to 3 m, and from
bathroom_a to the hall from 14 m (through bedroom_a) to 4 m."""
LEG_STEP_M = 0.2
"""The legs are looked at every this many metres for where they pass near each other."""
SIMPLIFY_M = 0.1
"""A route keeps only the points it needs to stay within this distance of its course (metres):
each point is a stop and a view taken for the way back, and ``toploc map record`` keeps a
position every 0.1 m driven."""


def leg_graph(places: Sequence[Place], junction_m: float = JUNCTION_M) -> nx.Graph:
    """The places joined by the legs they were recorded on, as a graph to find routes in: its
    nodes are place ids and points along the legs (tuples), each with its position ``xy``
    (drive frame, metres); its edges join each node to the next along a leg, and two points of
    legs of one drive that pass within ``junction_m`` of each other (0: no such junctions), each
    with its ``length_m``. A route need not retrace the drive's detours: where the drive crossed
    the hall again on its way to the next room, it can turn there. Places without a leg (nor one
    from them) are not in it; a leg from a place that has no position, or that is not among
    ``places``, is left out. A junction joins legs of one drive only (legs joined through their
    places): another drive's odometry is another frame."""
    by_id = {place.id: place for place in places}
    legs: nx.Graph[int] = nx.Graph()
    roads: nx.Graph[RoadNode] = nx.Graph()
    for place in places:
        leg = place.leg
        origin = by_id.get(leg.from_place) if leg is not None else None
        if leg is None or origin is None or origin.xy_m is None or place.xy_m is None:
            continue
        legs.add_edge(origin.id, place.id)
        dense = _densified((origin.xy_m, *leg.via_xy_m, place.xy_m), LEG_STEP_M)
        along: list[RoadNode] = [origin.id, *((place.id, k) for k in range(1, len(dense) - 1))]
        along.append(place.id)
        for node, at in zip(along, dense, strict=True):
            roads.add_node(node, xy=at)
        for u, v in itertools.pairwise(along):
            roads.add_edge(u, v, length_m=math.dist(roads.nodes[u]["xy"], roads.nodes[v]["xy"]))
    if junction_m > 0 and len(roads):
        drives = enumerate(nx.connected_components(legs))  # one drive: one odometry frame
        drive = {place: k for k, piece in drives for place in piece}
        nodes: list[RoadNode] = list(roads.nodes)
        pieces = [drive[node if isinstance(node, int) else node[0]] for node in nodes]
        xy = np.array([roads.nodes[node]["xy"] for node in nodes], dtype=np.float64)
        for i, j in cKDTree(xy).query_pairs(junction_m):
            if pieces[i] == pieces[j] and not roads.has_edge(nodes[i], nodes[j]):
                roads.add_edge(nodes[i], nodes[j], length_m=math.dist(xy[i], xy[j]))
    return roads


def _densified(points: Sequence[tuple[float, float]], step_m: float) -> list[tuple[float, float]]:
    """``points`` with points added on each segment so that none is longer than ``step_m``."""
    dense = [points[0]]
    for (x0, y0), (x1, y1) in itertools.pairwise(points):
        n = max(1, math.ceil(math.dist((x0, y0), (x1, y1)) / step_m))
        dense.extend((x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n) for k in range(1, n))
        dense.append((x1, y1))
    return dense


def _simplified(
    points: Sequence[tuple[float, float]], tolerance_m: float
) -> tuple[tuple[float, float], ...]:
    """``points`` (a polyline) without the points it can do without while staying within
    ``tolerance_m`` of them (Douglas-Peucker, ``cv2.approxPolyDP``); the ends are kept exact."""
    if len(points) <= 2:
        return tuple(points)
    curve = np.asarray(points, dtype=np.float32).reshape(-1, 2)
    kept = cv2.approxPolyDP(curve.reshape(-1, 1, 2), tolerance_m, False).reshape(-1, 2)
    indices, k = [], 0
    for point in kept:  # a subset of the points, in order, as float32: back to the points
        while not np.array_equal(curve[k], point):
            k += 1
        indices.append(k)
    return tuple(points[i] for i in indices)


WAY_IN_BACK_M = (0.3, 2.0)
"""The stretch of a leg, in metres driven before its place, whose direction of travel
:func:`way_in_rad` takes as the way the drive came in."""


def way_in_rad(place: Place, start: Place) -> float | None:
    """The drive-frame bearing (radians) the recording drive was going in as it came into
    ``place``'s room: from the leg's position :data:`WAY_IN_BACK_M` ``[1]`` metres driven
    before the place (or the leg's start, if nearer) to its position ``[0]`` metres before it.
    ``start``: the place the leg starts at. None when ``place`` has no pose or is not the end
    of a leg from ``start``, ``start`` is of the same room, or the leg is too short.

    The door lies on the leg, and a user records the first place of a room a little way past
    it, often after a turn: the way the drive went through the door points into the room from
    the place, where the direction from the door to the place may run along the wall (world
    seed 59's house: a place recorded 0.5 m back from 0.6 m past the door, 0.2 m inside)."""
    here, leg = place.xy_m, place.leg
    if here is None or leg is None or leg.from_place != start.id or start.room == place.room:
        return None
    points = [here, *reversed(leg.via_xy_m)]
    if start.xy_m is not None:
        points.append(start.xy_m)
    if len(points) < 2:
        return None
    near_m, far_m = WAY_IN_BACK_M
    back = np.asarray(_densified(points, 0.05))
    driven_m = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(back, axis=0).T))])
    if driven_m[-1] < 2 * near_m:
        return None
    later = int(np.searchsorted(driven_m, near_m))
    earlier = int(np.searchsorted(driven_m, far_m, side="right")) - 1
    dx, dy = back[later] - back[earlier]
    return None if math.hypot(dx, dy) < near_m else math.atan2(dy, dx)


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
    points = _simplified([graph.nodes[node]["xy"] for node in paths[end]], SIMPLIFY_M)
    return Route(start, end, points[0], points[1:], float(lengths[end]))


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


def route_beyond(
    graph: nx.Graph,
    places: Sequence[Place],
    room: str,
    lookalikes: Mapping[str, frozenset[str]],
    doors: Mapping[str, frozenset[str]],
    max_length_m: float,
) -> Route | None:
    """The shortest recorded route (at most ``max_length_m``) from a place of ``room`` on
    beyond the hall it shares with its look-alikes (``lookalikes``: each room's;
    :func:`shared_rooms`, ``doors``: each room's neighbours) to a room without look-alikes;
    None if there is none. ``graph``: the places' :func:`leg_graph`."""
    leave = {name for name, twins in lookalikes.items() if twins}
    leave |= {room, *shared_rooms(doors, room, lookalikes.get(room, frozenset()))}
    routes = (
        route_out(graph, places, place.id, leave, max_length_m)
        for place in places
        if place.room == room
    )
    return min(
        (route for route in routes if route is not None),
        key=lambda route: (route.length_m, route.start),
        default=None,
    )


def rooms_with_routes_out(
    places: Sequence[Place],
    leave: Collection[str],
    max_length_m: float,
    rooms: Collection[str] | None = None,
    graph: nx.Graph | None = None,
) -> set[str]:
    """The rooms (of ``rooms``; None: any) with a place that has a recorded route (at most
    ``max_length_m``) to a room neither in ``leave`` nor the place's own; ``graph``: the
    places' :func:`leg_graph`, if built already."""
    graph = leg_graph(places) if graph is None else graph
    return {
        place.room
        for place in places
        if (rooms is None or place.room in rooms)
        and route_out(graph, places, place.id, {*leave, place.room}, max_length_m) is not None
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
