"""Drive frames fixed by views, for the drives of a route check
(:func:`localizer.route_checks.check_route`).

A robot that stands where a view was taken (a place's stored view, or a view it took on the
way) knows its pose in that view's frame, its heading by the rotation between the two views
(:func:`frame_by_view`, :func:`place_frame`). From there a recorded route is driven by odometry
(:mod:`localizer.routes`): on from a hall place to a room beyond (:func:`onward_route`), back
from a route's end place into a look-alike (:func:`way_back_route`), or back through the views
taken on the way out, homing to each (:func:`back_by_marks`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from localizer.localizer import Localizer
from localizer.robot_protocol import Pose2D, Robot
from localizer.routes import (
    DriveFrame,
    Route,
    drive_route,
    route_into,
    route_out,
    route_through,
)
from localizer.turn_compass import CompassedRobot
from localizer.visual_homing import (
    HomingError,
    HomingParams,
    HomingResult,
    StepParams,
    drive_home,
    matched_inliers,
)
from mapdb.records import Fingerprint


def frame_by_view(
    current: Fingerprint, view: Fingerprint, pose: Pose2D, odometry: Pose2D, step: StepParams
) -> DriveFrame | None:
    """A drive frame fixed for a robot whose view ``current`` (taken at odometry ``odometry``,
    the robot not moved since) was taken where ``view`` was, at ``pose`` in that frame (a
    place's stored view and pose, or a view the robot took on the drive and its odometry
    then): the robot at ``pose``'s position, its heading ``pose``'s turned by the rotation
    between ``current`` and ``view``; None if they do not match."""
    try:
        _, shift_rad = matched_inliers(current, view, step)
    except HomingError:
        return None
    at = Pose2D(pose.x_m, pose.y_m, pose.heading_rad - shift_rad)
    return DriveFrame(at, odometry)


def place_frame(
    localizer: Localizer, place_id: int, current: Fingerprint, odometry: Pose2D, step: StepParams
) -> DriveFrame | None:
    """:func:`frame_by_view` for place ``place_id``'s stored view and pose; None if the place
    has no stored pose or the views do not match."""
    place = localizer.map.place(place_id)
    if place.x_m is None or place.y_m is None or place.heading_deg is None:
        return None
    stored = Pose2D(place.x_m, place.y_m, math.radians(place.heading_deg))
    return frame_by_view(current, localizer.map.fingerprint(place_id), stored, odometry, step)


@dataclass(frozen=True)
class Mark:
    """A view the robot took on a route, and its pose then (drive frame, by odometry)."""

    view: Fingerprint
    pose: Pose2D


def back_by_marks(
    localizer: Localizer,
    robot: CompassedRobot,
    marks: Sequence[Mark],
    frame: DriveFrame,
    start: Pose2D,
    homing: HomingParams,
) -> tuple[float, int, bool]:
    """Drive back through ``marks`` (last first) to ``start``'s position: at each, home to its
    view and fix the drive frame again by it (``frame`` is the one of the way out). Returns the
    odometric metres driven, the frames the homings captured, and whether the way back held:
    the homing to the last mark homed to (the first taken, nearest the start) arrived, and so
    did more than half of the homings to its marks (or there were none). A way back whose
    homings to its marks do not arrive may end anywhere: on world seed 39's building (two
    places per room), a robot in office_a whose homings to all seven of its marks gave up in
    the seminar room and the corridor came back into office_b and homed at once to the spot of
    office_a's place there (its check had arrived: sure and wrong, 0.997); of the other 30
    ways back on that map, every last mark was reached. On world seed 47's building (one place
    per room), a robot in office_a whose homings to six of its eight marks gave up reached the
    last, nearest the start, in office_b, the start's twin: the check's miss was folded in,
    and the belief favoured office_a, 0.82, for a robot now in office_b. Of 210 ways back in
    six runs (seeds 37-47, both worlds, one and two places per room), 4 ended in another room
    than they left, and had reached 0-2 of their 7-13 marks; the other 206 had reached their
    last mark and at least 3 of 5 (60 %)."""
    distance, frames, reached = 0.0, 0, []
    for mark in (*reversed(marks), None):
        here = frame.pose(robot.odometry())
        to = (start.x_m, start.y_m) if mark is None else (mark.pose.x_m, mark.pose.y_m)
        distance += drive_route(robot, route_through((here.x_m, here.y_m), (to,)), frame).distance_m
        if mark is None:
            break
        # homing steers by its views: the bare robot, no compass on its turns
        homed = drive_home(robot.robot, mark.view, localizer.extract, homing)
        distance += homed.distance_m
        frames += len(homed.lengths)
        again = (
            frame_by_view(homed.last, mark.view, mark.pose, robot.odometry(), homing.step)
            if homed.arrived
            else None
        )
        frame = again or frame
        reached.append(homed.arrived)
        if homed.arrived:  # it stands where it took its last view
            robot.seen(homed.last)
    held = not reached or (reached[-1] and 2 * sum(reached) > len(reached))
    return distance, frames, held


def onward_route(
    localizer: Localizer,
    robot: Robot,
    room: str,
    place_id: int,
    homed: HomingResult,
    route_max_m: float,
    step: StepParams,
) -> tuple[Route, DriveFrame] | None:
    """A recorded route from place ``place_id`` (in a room ``room`` opens onto, where ``homed``
    arrived at once) on to a room beyond: neither ``room`` nor a room it opens onto (the map's
    edges) nor one with a look-alike, up to ``route_max_m`` long; and the drive frame fixed by
    the place's stored view. None if there is no such route or the frame cannot be fixed.

    A route into a hall tells little where the hall repeats: driven from a look-alike that
    opens onto it, it ends a look-alike's offset along the hall, where the view is the end
    place's and homing arrives at once (world seed 39's house recorded one place per room:
    hall checks arrived from the look-alike in 4 of 5 and ended three kidnappings sure and
    wrong, 0.973). Re-anchored at the hall place, the drive on to a room beyond ends there
    only if the robot was at the hall place, and from the look-alike's door it ends a
    look-alike's offset off, where the room beyond does not repeat."""
    doors = localizer.doors
    leave = {name for name, twins in localizer.lookalikes.items() if twins}
    leave |= {room, *doors.get(room, frozenset())}
    on = route_out(localizer.map.legs, localizer.map.places, place_id, leave, route_max_m)
    return _from_known(localizer, robot, place_id, homed, on, step)


def _from_known(
    localizer: Localizer,
    robot: Robot,
    place_id: int,
    homed: HomingResult,
    route: Route | None,
    step: StepParams,
) -> tuple[Route, DriveFrame] | None:
    """``route`` (from place ``place_id``) and the drive frame fixed by the place's stored view
    where ``homed`` arrived (:func:`known_frame`); None if there is no route or no frame."""
    if route is None:
        return None
    frame = known_frame(localizer, robot, place_id, homed, step)
    return None if frame is None else (route, frame)


def joined_route(first: Route, then: Route) -> Route:
    """``first`` and ``then`` (which starts at ``first``'s end) as one route."""
    return Route(
        first.start,
        then.end,
        first.start_xy_m,
        first.waypoints_xy_m + then.waypoints_xy_m,
        first.length_m + then.length_m,
    )


def known_frame(
    localizer: Localizer, robot: Robot, place_id: int, homed: HomingResult, step: StepParams
) -> DriveFrame | None:
    """The drive frame fixed by place ``place_id``'s stored view and pose, where ``homed``
    arrived; None if it did not, the place has no stored pose or the views do not match."""
    if not homed.arrived:
        return None
    return place_frame(localizer, place_id, homed.last, robot.odometry(), step)


def way_back_route(
    localizer: Localizer,
    robot: Robot,
    end: int,
    at_end: HomingResult,
    into: str,
    route_max_m: float,
    step: StepParams,
) -> tuple[Route, DriveFrame] | None:
    """A recorded route from place ``end``, where homing ``at_end`` brought the robot, into
    room ``into`` (up to ``route_max_m`` long), and the drive frame fixed by ``end``'s stored
    view; None if the homing did not arrive, ``end`` has no stored pose, no route leads there
    or the views do not match."""
    route = route_into(localizer.map.legs, localizer.map.places, end, {into}, route_max_m)
    return _from_known(localizer, robot, end, at_end, route, step)
