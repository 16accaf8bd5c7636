"""Checking a likely room by a recorded route (:mod:`localizer.routes`): the drive the active
loop (:mod:`localizer.active`) makes when no place tells the likely rooms apart (look-alike
rooms that look alike from every place of theirs).

The robot homes to a place of the room, drives the route the map recorded from there into
another room and homes to the route's end place. If it started in that room, it is at the end
place when the route ends and homes there at once; if it started in a look-alike, the same
drive ends elsewhere (:class:`RouteCheck`). The robot drives back through the views it took on
the way out, homing to each, to the start; there the check is folded into the belief. A route
that ends in a room its room opens onto (a hall, where a look-alike's door may repeat the view
a look-alike's offset along) goes on from the end place, re-anchored there, to a room beyond.
A check that arrived at a place beyond the rooms its room opens onto fixed the robot's
odometry in the map's frame there: if the way back ends where the map has the start place, the
robot retraced the map's route and is in that room (from a look-alike it ends a look-alike's
offset away). If the homing to the end place arrived but late, the robot is at a known place
of a room without look-alike, and drives a recorded route from there into the look-alike
instead: the room whose place it then reaches at once gains the odds.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

from localizer.localizer import Localizer
from localizer.robot_protocol import Pose2D, Robot
from localizer.route_frames import (
    Mark,
    back_by_marks,
    frame_by_view,
    joined_route,
    known_frame,
    onward_route,
    way_back_route,
)
from localizer.routes import (
    ROUTE_MAX_M,
    DriveFrame,
    Route,
    drive_route,
    route_beyond,
    shared_rooms,
)
from localizer.turn_compass import CompassedRobot
from localizer.visual_homing import (
    CANCELLED,
    HomingParams,
    HomingResult,
)
from mapdb.records import Place


@dataclass(frozen=True)
class RouteCheckParams:
    """How a room is checked by a recorded route (:class:`RouteCheck`, :func:`check_route`): routes
    up to ``route_max_m`` long; the robot "arrived at once" when homing to the route's end place
    arrives after at most ``route_slack_m`` plus ``route_slack_share`` of the route's length
    (the odometry's drift over the route), never more than ``route_slack_max_m``, its odometry
    then has it within that drift of the end place too, and the look there names the end place's
    room. The cap: a route driven from a twin can end where the end place is in sight a few
    metres on (world seed 31's house: bedroom_b's 11 m route into the living room, driven from
    bedroom_a, stopped at the hall's end, and homing reached the living room's place after
    4.0 m, within the 4.3 m the share allowed); of 885 checks that arrived from the route's own room
    in sessions 23-26's runs, 15 took more than 2.5 m, of 257 from elsewhere 20.
    ``route_hit_rate``: how often that happens when the robot did start in the route's room;
    ``route_false_rate``: when it started elsewhere. A check that arrives multiplies its room's
    odds by their ratio (8), one that does not by ``(1 - hit) / (1 - false)`` (0.22), once the
    robot is back at the start. On the maps of world seeds 17–20 recorded on one drive (K = 1,
    2, 3; session 21's runs of ``benchmarks/bench_recorded_maps.py``), 205 of the 244 checks
    back at the start arrived when the robot was in the route's room (0.84, 90 % interval
    0.80–0.88), and 4 of 166 when it was in another (0.024, interval 0.008–0.054): the hit rate
    is the interval's low end, and the false rate stays at the 0.1 set on seeds 14 and 15
    (session 20), twice the interval's high end, as a twin whose doors stand alike fools every
    check of it, not one in forty. So one check that arrives leaves the belief ambiguous (8 <
    the localized ratio 10); with its look-alike's check that did not, 36; one whose way back
    retraced the map's route (:func:`_retraced`), 64. ``hall_route_hit_rate`` and
    ``hall_route_false_rate`` take their place for a route that ends in the hall the room's
    look-alikes open onto too (:func:`shared_rooms`) when none of them has a recorded route
    beyond it: driven from a twin, such a route ends in that hall as well, a twin's offset along
    it, and where the hall looks alike at both doors it arrives there too. Over the first checks
    of a room in world seeds 27–29's runs, hall routes arrived in 42 of 66 checks from their own
    room and 30 of 78 from elsewhere (0.64 and 0.38; on seven of thirteen maps of seeds 25–29
    they told the truth, on six they told nothing). Where a look-alike has a route beyond, the
    pair's two checks tell together: where one arrived and the other did not, the robot was in
    the room of the one that arrived 76 times in 77 (seeds 25–30), so such a pair keeps the
    rates above (docs/results.md, session 25). The way back is checked the same way: homing to
    the place the drive back leads to arrives at once, or the robot may be in any room and the
    belief starts afresh from the next look (two kidnappings of world seed 13 ended sure of a
    room the robot was not in, after a way back that failed). ``compass_min_turn_deg``: the
    route drives measure each turn at least this large (degrees) by the camera
    (:mod:`localizer.turn_compass`); infinity keeps the odometry's turns."""

    route_max_m: float = ROUTE_MAX_M
    route_hit_rate: float = 0.8
    route_false_rate: float = 0.1
    hall_route_hit_rate: float = 0.65
    hall_route_false_rate: float = 0.4
    route_slack_m: float = 1.0
    route_slack_share: float = 0.3
    route_slack_max_m: float = 2.5
    compass_min_turn_deg: float = 15.0

    def __post_init__(self) -> None:
        if not self.compass_min_turn_deg > 0:
            raise ValueError(f"compass_min_turn_deg must be > 0, got {self.compass_min_turn_deg}")
        for name in ("route", "hall_route"):
            hit, false = getattr(self, f"{name}_hit_rate"), getattr(self, f"{name}_false_rate")
            if not 0.0 < false < hit < 1.0:
                raise ValueError(
                    f"need 0 < {name}_false_rate < {name}_hit_rate < 1, got {false} and {hit}"
                )


@dataclass(frozen=True)
class RouteCheck:
    """One room checked by a recorded route: the robot homed to place ``start`` of ``room``,
    drove the route to place ``end`` (of another room), homed to it, and drove back;
    ``confirmed``: the homing to ``end`` arrived at once and the look there named ``end``'s
    room (the robot was where the route ends if it started in ``room``); ``distance_m``:
    odometric metres of the whole check; ``end_inliers``: the spread inliers of that look
    with ``end``'s view (0 if the homing did not arrive);
    ``end_homing_m``: how far the homing to ``end`` drove (0: the route was not driven);
    ``back_room``: the room the robot came back to (``room``, through the views it took on the
    way out, though its homing to ``start`` may not have arrived; or ``room``'s look-alike,
    whose place a recorded route from ``end`` reached at once), where the check was folded into
    the belief (unless an earlier check of the room came out the same, see
    :func:`check_route`); None: it did not, and the belief started afresh or was kept.
    ``started``: homing to ``start`` arrived and the route was driven; ``afresh``: the robot
    did not get back to a place it knew, and the belief started afresh (what earlier checks
    told is gone with it); ``via``: the place of a room ``room`` opens onto that the
    route reached at once and went on from to ``end`` (None: it went straight to ``end``;
    :func:`~localizer.route_frames.onward_route`)."""

    room: str
    start: int
    end: int
    confirmed: bool
    distance_m: float
    end_inliers: float = 0.0
    end_homing_m: float = 0.0
    back_room: str | None = None
    started: bool = True
    afresh: bool = False
    via: int | None = None

    @property
    def first_end(self) -> int:
        """The end place of the route the check began with (``via`` if it went on from
        there): the end :func:`~localizer.route_choice.route_to_check` chose."""
        return self.end if self.via is None else self.via


def check_route(
    localizer: Localizer,
    robot: Robot,
    home: Callable[[int], HomingResult],
    start: Place,
    route: Route,
    rival: str | None,
    params: RouteCheckParams,
    homing: HomingParams,
    told: frozenset[bool] = frozenset(),
) -> tuple[RouteCheck, int, HomingResult, int | None]:
    """Check ``start``'s room by ``route`` (see :class:`RouteCheck`; ``home(place_id)`` drives
    the robot to a place, ``homing`` the settings of the homings to the views it takes on the
    way) and fold the result into the localizer's belief. The result is folded in only if no earlier
    check of the room came out the same (``told``: the outcomes, arrived or not, of the
    earlier checks of the room that came back): the checks of one room fail or pass together
    (a door its homing does not pass, odometry that drifts the same way on the same leg, an
    end place whose view repeats where the twin's route ends). Two misses taken as independent
    made a robot in the room sure of its twin (world seed 25's house, two places per room: two
    checks of the bedroom the robot was in failed, 0.54 for it became 0.034); two arrivals
    made a robot sure of the twin it was not in (world seed 27's house, see
    :func:`~localizer.route_choice.rooms_to_check`). The way back: if homing to the route's end
    place arrived but not at once, by a recorded route from there into ``rival`` (``start``'s
    likely look-alike, if any); otherwise back along the views taken on the way out, to
    ``start``, where a check that arrived at once is folded in again if the robot stands where
    the map has ``start`` (:func:`_retraced`); a way back that holds (it reaches the first view
    it took, in the room it left) tells the check though its homing to ``start`` may not
    arrive, one that does not starts the belief afresh. A check whose homing to ``start`` does not
    arrive drives no route: the robot homes back to the place it stood at, if it stood at one.
    A route that ends in a room ``start``'s room opens onto, reached at once, goes on from its
    end place to a room beyond (:func:`~localizer.route_frames.onward_route`), and the check
    is of the two legs together.
    Returns the check, the frames captured (the turn compass's too), the homing to the route's
    end place and the place the robot homed to last (None: it stands where no homing
    arrived), to look from."""
    assert start.x_m is not None and start.y_m is not None and start.heading_deg is not None
    stood_at = localizer.latest.at_place if localizer.latest is not None else None
    to_start = home(start.id)
    stored = Pose2D(start.x_m, start.y_m, math.radians(start.heading_deg))
    # routes are driven, and drive frames kept, on odometry whose turns the camera measured
    steered = CompassedRobot(
        robot,
        lambda capture: localizer.extract(capture.image),
        homing.step,
        math.radians(params.compass_min_turn_deg),
    )
    view = localizer.map.fingerprint(start.id)
    frame = frame_by_view(to_start.last, view, stored, steered.odometry(), homing.step)
    out = None
    back = _Back(None, False, start.id if to_start.arrived else None)
    if frame is not None and to_start.arrived:  # a route driven from elsewhere tells nothing
        out = _drive_out(localizer, steered, home, start, route, frame, params, homing)
        back = _come_back(localizer, steered, home, start, out, frame, rival, params, homing, told)
    elif not to_start.arrived and stood_at is not None and to_start.reason != CANCELLED:
        # the check could not start: back to the place the robot stood at, not left where the
        # homing gave up (world seed 30's house, one place per room: a robot at bedroom_b's
        # place by its door, whose homing to the hall's place gave up in the hall, looked there
        # and ended sure of bedroom_b, 0.977, no longer in it)
        homed = home(stood_at)
        homed_to = stood_at if homed.arrived else None
        back = _Back(None, False, homed_to, homed.distance_m, len(homed.lengths))
    if not to_start.arrived and to_start.reason != CANCELLED and localizer.alone(start.room):
        # a robot in a room homes to its one place from anywhere in it: the looks that made it
        # likely may have come from a room whose walls look like a part of it (world seed 95's
        # building, one place per room: three robots in the offices, whose frames matched the
        # kitchen's place on under half the horizon, could not home to it and ended 0.97-0.98
        # for the kitchen, every further look adding to it)
        localizer.doubt(start.room)
    at_end = to_start if out is None else out.at_end
    started = at_end is not to_start  # the route was driven
    check = RouteCheck(
        start.room,
        start.id,
        route.end if out is None else out.route.end,
        out is not None and out.confirmed,
        to_start.distance_m + (0.0 if out is None else out.distance_m) + back.distance_m,
        0.0 if out is None else out.end_inliers,
        at_end.distance_m if started else 0.0,
        back.room,
        started,
        back.afresh,
        None if out is None else out.via,
    )
    frames = len(to_start.lengths) + (0 if out is None else out.frames) + back.frames
    return check, frames + steered.views, at_end, back.homed_to


@dataclass(frozen=True)
class _Out:
    """How the drive out of a route check went: the ``route`` driven (its legs joined, if it
    went on from ``via``), the homing to its end place (``at_end``), whether the look there
    named the end place's room (``seen``) with ``end_inliers`` spread inliers, whether it
    arrived at once (``confirmed``), the views taken on the way (``marks``), and the metres
    and frames it took (the turn compass's views not counted)."""

    route: Route
    at_end: HomingResult
    seen: bool
    end_inliers: float
    confirmed: bool
    via: int | None
    marks: tuple[Mark, ...]
    distance_m: float
    frames: int


@dataclass(frozen=True)
class _Back:
    """How the way back of a route check went: the ``room`` whose place the robot came back to
    at once (None: it did not), whether the belief started ``afresh``, the place the robot
    homed to last (``homed_to``; None: it stands where no homing arrived), and the metres and
    frames it took."""

    room: str | None
    afresh: bool
    homed_to: int | None
    distance_m: float = 0.0
    frames: int = 0


def _drive_out(
    localizer: Localizer,
    steered: CompassedRobot,
    home: Callable[[int], HomingResult],
    start: Place,
    route: Route,
    frame: DriveFrame,
    params: RouteCheckParams,
    homing: HomingParams,
) -> _Out:
    """Drive ``route`` from ``start``, where the robot stands (``frame`` fixed there), taking a
    view at each waypoint, home to its end place and look there (see :func:`check_route`)."""
    robot = steered.robot
    marks: list[Mark] = []

    def mark(_: int) -> None:  # a view at each waypoint: the way back homes to them
        pose = frame.pose(steered.odometry())
        marks.append(Mark(localizer.extract(robot.capture().image), pose))
        steered.seen(marks[-1].view)  # the turn toward the next waypoint starts here

    distance, frames, via = 0.0, 0, None
    leg, leg_frame = route, frame
    while True:
        distance += drive_route(steered, leg, leg_frame, mark).distance_m
        at_end = home(leg.end)
        distance += at_end.distance_m
        frames += len(at_end.lengths)
        seen, end_inliers = False, 0.0
        if at_end.arrived:
            seen, end_inliers = _look_at_end(localizer, robot, leg.end)
            frames += 1
        # at once, and the look there names the end room (which has no look-alike): a
        # homing that arrives is no proof (on world seed 15, 4 of 27 checks of a twin the
        # robot was not in arrived at once)
        confirmed = seen and _at_once(at_end, leg, params, steered, leg_frame)
        onward = None
        if confirmed and via is None and not _beyond_the_hall(localizer, start.room, leg):
            onward = onward_route(
                localizer, steered, start.room, leg.end, at_end, params.route_max_m, homing.step
            )
        if onward is None or at_end.reason == CANCELLED:
            break
        via, (leg, leg_frame) = leg.end, onward
        route = joined_route(route, leg)
    frames += len(marks)
    return _Out(route, at_end, seen, end_inliers, confirmed, via, tuple(marks), distance, frames)


def _come_back(
    localizer: Localizer,
    steered: CompassedRobot,
    home: Callable[[int], HomingResult],
    start: Place,
    out: _Out,
    frame: DriveFrame,
    rival: str | None,
    params: RouteCheckParams,
    homing: HomingParams,
    told: frozenset[bool],
) -> _Back:
    """The way back of a route check driven out (``out``) from ``start`` (``frame`` fixed
    there), and what it tells (see :func:`check_route`)."""
    route, at_end = out.route, out.at_end
    if at_end.reason == CANCELLED:
        return _Back(None, False, route.end if at_end.arrived else None)
    if out.seen and not out.confirmed and rival is not None:  # at the end place, known
        way_back = way_back_route(
            localizer, steered, route.end, at_end, rival, params.route_max_m, homing.step
        )
        if way_back is not None:
            return _back_into_rival(localizer, steered, home, *way_back, params)
    # at the end place, a known place, the robot's odometry is fixed in the map's frame:
    # coming back to where the map has the start place, it retraced the recorded route
    known = None
    if out.confirmed and _end_fixes_the_frame(localizer, start.room, route, out.via):
        known = known_frame(localizer, steered, route.end, at_end, homing.step)
    # back through the views taken on the way out, each homed to (a frame fixed at the
    # route's end, 8 m from the door, put the robot 0.75 m off it: world seed 15)
    assert start.x_m is not None and start.y_m is not None and start.heading_deg is not None
    stored = Pose2D(start.x_m, start.y_m, math.radians(start.heading_deg))
    driven_m, homings, held = back_by_marks(localizer, steered, out.marks, frame, stored, homing)
    back = home(start.id)
    homed_to = start.id if back.arrived else None
    done = _Back(None, False, homed_to, driven_m + back.distance_m, homings + len(back.lengths))
    if not held:  # it may be in any room now: the look decides
        localizer.reset()
        return replace(done, afresh=True)
    # back at the first view it took on the way out, in the room it left (of 210 ways back in
    # session 30's runs, the 206 that held ended there), though its homing to the start may not
    # have arrived at once: the check tells about that room (world seed 93's building, one
    # place per room: robots in office_b whose check of office_a missed, and whose homing back
    # to office_a's place in office_b converged short of it, ended at 0.88 when the miss was
    # not told)
    if not out.confirmed and localizer.alone(start.room):
        # its looks may have been an unknown twin's (world seed 97's building, one place per
        # room, twins the calibration did not pair: a robot in office_b whose check of
        # office_a missed came back near office_a's place's spot in office_b, short of it, and
        # the look there, 251 inliers with office_a's place, made it sure of office_a, 1.000)
        localizer.doubt(start.room)
    if out.confirmed not in told:
        hall = _hall_check_alone(localizer, start.room, route, params)
        ratio = _route_ratio(params, hall) if out.confirmed else _miss_ratio(params, hall)
        if (
            _at_once(back, route, params)
            and known is not None
            and _retraced(known, steered, start, route, params)
        ):
            ratio *= _route_ratio(params)  # it is in start's room now, by the map
        localizer.update_rooms({start.room: ratio})
    return replace(done, room=start.room)


def _back_into_rival(
    localizer: Localizer,
    steered: CompassedRobot,
    home: Callable[[int], HomingResult],
    back_route: Route,
    back_frame: DriveFrame,
    params: RouteCheckParams,
) -> _Back:
    """At a route's end place, in a room without a look-alike, the robot knows where it is, and
    ``back_route`` from there leads into the look-alike the check did not refute: if the robot
    reaches a place of it at once, it is there (its odds multiplied by the route ratio); if
    not, it is somewhere along the way back and the belief starts afresh."""
    distance = drive_route(steered, back_route, back_frame).distance_m
    back = home(back_route.end)
    homed_to = back_route.end if back.arrived else None
    done = _Back(None, False, homed_to, distance + back.distance_m, len(back.lengths))
    if _at_once(back, back_route, params, steered, back_frame):
        room = localizer.map.place(back_route.end).room
        localizer.update_rooms({room: _route_ratio(params)})
        return replace(done, room=room)
    localizer.reset()  # somewhere along the way back: the look decides
    return replace(done, afresh=True)


def _beyond_the_hall(localizer: Localizer, room: str, route: Route) -> bool:
    """Whether ``route`` out of ``room`` ends beyond the rooms ``room`` opens onto (the map's
    edges): a hall a room opens onto may have a look-alike's door a look-alike's offset along
    it, where the view is the end place's, and a check driven from the look-alike that stops
    there arrives as if at the end place, with the robot's odometry then fixed a look-alike's
    offset off; its way back to the look-alike then ends where the map has the start place
    (world seed 39's house recorded one place per room: three robots whose checks into the
    hall, arriving on 12-26 spread inliers, had left them sure of the twin they were not in,
    0.973, were made surer, 0.997 for two, when the rule left out only halls the map knows
    both twins open onto)."""
    end_room = localizer.map.place(route.end).room
    return end_room not in localizer.doors.get(room, frozenset())


def _end_fixes_the_frame(localizer: Localizer, room: str, route: Route, via: int | None) -> bool:
    """Whether reaching ``route``'s end place at once (the route out of ``room``, on from place
    ``via`` if it went on beyond a hall) fixes the robot's odometry in the map's frame: the end
    is beyond the hall (:func:`_beyond_the_hall`), and no twin the map does not know can stand
    where the route, driven from ``room``'s look-alike, would end. A room of one place with no
    look-alike (:meth:`Localizer.alone`) may have one: the map cannot tell from one view, and a
    copy of the look-alike's wing puts the end room's twin at the look-alike's offset (world
    seed 43's house, one place per room: bathroom_b is a copy of bathroom_a, its twin unknown
    to the map; robots in bedroom_a drove bedroom_b's route into bathroom_b, arrived at once
    in bathroom_a, came back "retraced" to where the map has bedroom_b's place and ended sure
    of bedroom_b, 0.96-0.985, in 3 of 5 kidnappings). A route that went on from a hall place
    was fixed there, in the hall both look-alikes open onto, and its end is not at a twin's
    offset (:func:`~localizer.route_frames.onward_route`)."""
    if not _beyond_the_hall(localizer, room, route):
        return False
    return via is not None or not localizer.alone(localizer.map.place(route.end).room)


def _retraced(
    known: DriveFrame, robot: Robot, start: Place, route: Route, params: RouteCheckParams
) -> bool:
    """Whether the robot, back by its own views from the end place of ``route`` (where its
    odometry was fixed in the map's frame, ``known``), stands where the map has ``start``,
    within the odometry's drift over the route (as :func:`_at_once`): then the way it came is
    the map's route, and it is in ``start``'s room. A robot that started in a look-alike and
    still arrived at the end place comes back a look-alike's offset away."""
    assert start.x_m is not None and start.y_m is not None
    return _odometry_at(robot, known, (start.x_m, start.y_m), route, params)


def _odometry_at(
    robot: Robot,
    frame: DriveFrame,
    xy_m: tuple[float, float],
    route: Route,
    params: RouteCheckParams,
) -> bool:
    """Whether the robot's odometry, in drive ``frame``, puts it at ``xy_m`` (the frame's
    metres) within the odometry's drift over ``route``."""
    here = frame.pose(robot.odometry())
    return math.dist((here.x_m, here.y_m), xy_m) <= _slack_m(route, params)


def _slack_m(route: Route, params: RouteCheckParams) -> float:
    """How far from a place reached by ``route`` the robot may stand by odometry alone: the
    odometry's drift over the route (:class:`RouteCheckParams`)."""
    return min(
        params.route_slack_m + params.route_slack_share * route.length_m, params.route_slack_max_m
    )


def _at_once(
    homed: HomingResult,
    route: Route,
    params: RouteCheckParams,
    robot: Robot | None = None,
    frame: DriveFrame | None = None,
) -> bool:
    """Whether homing to ``route``'s end place, after driving the route, arrived at once: after
    at most the odometry's drift over the route (:class:`RouteCheckParams`), and, given the
    ``robot`` and the drive ``frame`` the route was driven in, where its odometry has the end
    place, within that drift too. A route that does not fit the room it is driven from (a
    look-alike's, a twin's offset off) can stop against a wall a few metres short, in sight of
    the end place: homing then covers the rest, at once (world seed 47's building, one place
    per room: office_a's route into the corridor, driven from office_b, stopped against the
    corridor's end 0.8 m from its place, 3.5 m short of it by the odometry; homing arrived
    after 0.75 m, the check went on beyond, and the robot ended in office_b sure of office_a,
    0.973; its odometry had it 4.1-4.2 m off the corridor's place in all four such checks of
    that run, and at most 1.44 m off in the 146 checks that arrived at once from their own
    room in six runs, seeds 37-47, both worlds, one and two places per room)."""
    if not (homed.arrived and homed.distance_m <= _slack_m(route, params)):
        return False
    if robot is None or frame is None:
        return True
    return _odometry_at(robot, frame, route.waypoints_xy_m[-1], route, params)


def _route_rates(params: RouteCheckParams, hall: bool) -> tuple[float, float]:
    """How often a route check arrives at once from the route's room and from elsewhere; a
    check into the hall whose look-alikes have no route beyond it (``hall``) has its own."""
    if hall:
        return params.hall_route_hit_rate, params.hall_route_false_rate
    return params.route_hit_rate, params.route_false_rate


def _route_ratio(params: RouteCheckParams, hall: bool = False) -> float:
    """The likelihood ratio a route that arrived at once gives its room."""
    hit, false = _route_rates(params, hall)
    return hit / false


def _miss_ratio(params: RouteCheckParams, hall: bool = False) -> float:
    """The likelihood ratio a route that did not arrive at once gives its room."""
    hit, false = _route_rates(params, hall)
    return (1.0 - hit) / (1.0 - false)


def _hall_check_alone(
    localizer: Localizer, room: str, route: Route, params: RouteCheckParams
) -> bool:
    """Whether ``route`` out of ``room`` ends in a hall ``room``'s look-alikes open onto too
    (:func:`shared_rooms`) while none of them has a recorded route (up to ``route_max_m``) on
    beyond its own hall: the check then stands alone, at the hall's rates
    (:class:`RouteCheckParams`)."""
    twins = localizer.lookalikes.get(room, frozenset())
    doors = localizer.doors
    if localizer.map.place(route.end).room not in shared_rooms(doors, room, twins):
        return False
    graph, places, lookalikes = localizer.map.legs, localizer.map.places, localizer.lookalikes
    return not any(
        lookalikes.get(twin)
        and route_beyond(graph, places, twin, lookalikes, doors, params.route_max_m) is not None
        for twin in twins
    )


def _look_at_end(localizer: Localizer, robot: Robot, end: int) -> tuple[bool, float]:
    """Look where homing to place ``end`` arrived: whether the best-matching place is of
    ``end``'s room, and the spread inliers with ``end``'s view."""
    places = localizer.observe(robot.capture().image).evidence.places
    best = max(places, key=lambda item: item.spread_inliers, default=None)
    room = localizer.map.place(end).room
    seen = best is not None and localizer.map.place(best.place_id).room == room
    inliers = next((item.spread_inliers for item in places if item.place_id == end), 0.0)
    return seen, inliers
