"""Where the active loop (:func:`localizer.active.localize_actively`) looks once more before a
belief is taken: a place of the room the belief would settle on but for not seeing it all
round (:func:`closer_look`), a stored place of the room a ``localized`` belief names
(:func:`place_to_end_at`), and a step further into the room from a place recorded on the way
in through its door (:func:`way_in_step`).
"""

from __future__ import annotations

import math

from localizer.belief import LocalizationState
from localizer.localizer import Localizer
from localizer.looking_elsewhere import best_matched
from localizer.robot_protocol import Robot
from localizer.route_frames import place_frame
from localizer.routes import DriveFrame, way_in_rad
from localizer.visual_homing import StepParams


def closer_look(localizer: Localizer, looked: set[int]) -> int | None:
    """A place of the room the belief would settle on but for not seeing that room all round
    (:meth:`Localizer.unseen_room`), the first the robot has not homed to for this yet: the
    loop homes there and looks before it ends. Looking where the room's place stands asks
    what the all-round test asks, whether the robot is in that room and not at its door; the
    odds come from what came before (on world seeds 43 and 45's house recorded one place per
    room, 8 robots ended ambiguous at 36-49 times their room's twin, after their room's check
    arrived and the twin's missed, looking from the twin's place's spot in their own room,
    where their room's place covered less of the horizon; all 8 were right)."""
    room = localizer.unseen_room()
    if room is None:
        return None
    places = [place.id for place in localizer.map.places if place.room == room]
    return next((place_id for place_id in places if place_id not in looked), None)


def place_to_end_at(localizer: Localizer, looked: set[int]) -> int | None:
    """The place to home to before a ``localized`` belief is taken
    (:attr:`~localizer.active.ActiveParams.end_at_place`): of the belief's room, the place the
    latest frame verified with most spread inliers; None when the belief is not ``localized``,
    the latest frame was taken where the robot homed to a place of that room (or to its
    counterpart on one spot, :meth:`Localizer.same_spot_places`), the robot homed to one of its
    places for a closer look already (``looked``: once per room, even where that homing did not
    move it), or the frame verified no place of it."""
    belief, latest = localizer.belief(), localizer.latest
    if belief.state is not LocalizationState.LOCALIZED or latest is None:
        return None
    room = belief.top[0]
    homed = {localizer.map.place(place_id).room for place_id in looked}
    if latest.at_place is not None:  # its counterparts on that spot were looked from too
        for place_id in (latest.at_place, *localizer.same_spot_places(latest.at_place)):
            homed.add(localizer.map.place(place_id).room)
    if room in homed:
        return None
    return best_matched(
        [item for item in latest.evidence.places if item.room == room and item.inliers > 0]
    )


def way_in_step(
    localizer: Localizer, robot: Robot, step_m: float, step: StepParams, stepped: set[int]
) -> tuple[DriveFrame, tuple[float, float], int] | None:
    """Where to drive further into the room the belief is ``localized`` in, when the latest
    frame was taken at a place of that room recorded on a drive in from another room
    (:attr:`~localizer.active.ActiveParams.step_in_m`): the point ``step_m`` past the place
    along the way the drive came in (:func:`~localizer.routes.way_in_rad`), and the drive frame
    to steer to it in, fixed by the robot standing at the place when it took that frame, its
    heading by the frame's rotation against the place's stored view
    (:func:`~localizer.route_frames.place_frame`, as a route check fixes its frame at a place).
    Driven as a route (a step that bumps slides past: a robot homed into a doorway off its
    middle meets the door frame). The frame is fixed on a view taken where the robot stands: the
    latest frame's if the robot has not moved since (odometry), else a new capture (a route
    check that ends back at the place reuses the look taken there before it, and its odometry
    has drifted since: on world seed 83's house, one place per room, 20 m of route later it put
    the robot about 2 m and 44° off, and the step in drove out into the hall); with the captures
    made for it (0 or 1). None when there is no such place, it is in ``stepped`` (added to it:
    once per place), or the frame does not match its view."""
    belief, latest = localizer.belief(), localizer.latest
    if belief.state is not LocalizationState.LOCALIZED or latest is None:
        return None
    if latest.at_place is None or latest.at_place in stepped:
        return None
    place = localizer.map.place(latest.at_place)
    if place.room != belief.top[0] or place.leg is None:
        return None
    stepped.add(place.id)
    try:
        start = localizer.map.place(place.leg.from_place)
    except KeyError:  # the leg's start place was removed from the map since
        return None
    bearing_rad = way_in_rad(place, start)
    if bearing_rad is None:
        return None
    view, odometry_now, captured = latest.fingerprint, robot.odometry(), 0
    if odometry_now != latest.odometry:
        view, captured = localizer.extract(robot.capture().image), 1
    frame = place_frame(localizer, place.id, view, odometry_now, step)
    if frame is None:
        return None
    inside = (
        frame.at.x_m + step_m * math.cos(bearing_rad),
        frame.at.y_m + step_m * math.sin(bearing_rad),
    )
    return frame, inside, captured
