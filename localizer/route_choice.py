"""Which likely room to check by a recorded route next, and from where; the check itself is
:func:`localizer.route_checks.check_route`.

The likely rooms are taken in order (:func:`rooms_to_check`), each from a place of it with a
recorded route out to a room that has no look-alike (:func:`route_to_check`). What the checks
made so far have told decides what comes next: the outcomes of a room's checks since the
belief last started afresh (:func:`told_outcomes`), and the rooms where checks of two
look-alikes both arrived, which tell nothing (:func:`repeating_ends`).
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable, Collection, Mapping, Sequence

from localizer.belief import RoomBelief
from localizer.localizer import Localizer, Observation
from localizer.route_checks import RouteCheck, RouteCheckParams
from localizer.routes import (
    Route,
    route_beyond,
    route_out,
    shared_rooms,
)
from mapdb.records import Place

LIKELY_SHARE = 0.1
"""A room at least this share of the top room's probability is checked by a route too (a
refuted look-alike tells as much as a confirmed top room)."""


def told_outcomes(checks: Sequence[RouteCheck], room: str) -> frozenset[bool]:
    """The outcomes (:attr:`RouteCheck.confirmed`) the checks of ``room`` have told about it,
    folded in or already known: of the checks that came back to ``room``, since the belief
    last started afresh (:attr:`RouteCheck.afresh`: what a check told before then was about a
    belief that is gone, and a later check that comes out the same tells it again)."""
    last = max((i for i, check in enumerate(checks) if check.afresh), default=-1)
    return frozenset(
        check.confirmed
        for check in checks[last + 1 :]
        if check.room == room and check.back_room == room
    )


def repeating_ends(
    checks: Sequence[RouteCheck],
    lookalikes: Mapping[str, Collection[str]],
    room_of: Callable[[int], str],
) -> frozenset[str]:
    """The rooms (``room_of(place_id)``) where checks of two look-alike rooms
    (:attr:`Localizer.lookalikes`) both arrived at once since the belief last started afresh:
    the rooms their routes ended in (:attr:`RouteCheck.first_end`). The robot stood in at most
    one of the two rooms, so one of the two arrivals was false: the route from the other room
    ends where the first one's does, in a room the map does not know as a look-alike (world
    seed 85's house recorded one place per room: the map paired the bathrooms but not the
    bedrooms, each bathroom's route led into the bedroom beside it, both checks arrived, and
    the belief stayed at 0.5). A pair is taken in the order the checks were made, and one whose
    end is already among the rooms found is explained by them: a later check that arrived by
    a route ending elsewhere does not make its end repeat. Checks go on by routes that end
    elsewhere (:func:`route_to_check`'s ``avoid``), and an arrival there tells nothing
    (:func:`telling_checks`)."""
    last = max((i for i, check in enumerate(checks) if check.afresh), default=-1)
    arrived = [check for check in checks[last + 1 :] if check.confirmed]
    ends: set[str] = set()
    for one, other in itertools.combinations(arrived, 2):
        pair = {room_of(one.first_end), room_of(other.first_end)}
        if other.room in lookalikes.get(one.room, ()) and not pair & ends:
            ends |= pair
    return frozenset(ends)


def telling_checks(
    checks: Sequence[RouteCheck], repeating: Collection[str], room_of: Callable[[int], str]
) -> list[RouteCheck]:
    """``checks`` without the arrivals at a room of ``repeating`` (:func:`repeating_ends`),
    which told nothing; what :func:`told_outcomes` reads for the next check of a room, so that
    a telling arrival is counted once though a check of the room arrived there before. A miss
    there is kept (the room's other checks may miss by the same cause), and so is a check
    after which the belief started afresh (it marks where the told outcomes start)."""
    return [
        check
        for check in checks
        if check.afresh or not (check.confirmed and room_of(check.first_end) in repeating)
    ]


def starts_to_check_again(
    checks: Sequence[RouteCheck], repeating: Collection[str], room_of: Callable[[int], str]
) -> set[int]:
    """The start places of ``checks`` all of whose checks ended (:attr:`RouteCheck.first_end`)
    in a room of ``repeating``: a route from there that ends elsewhere may still tell."""
    starts = {check.start for check in checks}
    return {
        start
        for start in starts
        if all(room_of(c.first_end) in repeating for c in checks if c.start == start)
    }


def rooms_to_check(belief: RoomBelief, checked: Mapping[str, int]) -> list[str]:
    """The likely rooms (at least :data:`LIKELY_SHARE` of the top room's probability) in the
    order to check them by a route: the rooms checked fewer times (``checked``, by room) first,
    then the more likely. A room's checks share their end place and its view, and fail or pass
    together: a check that arrived is followed by its rival's, not by the same room's again
    (world seed 27's house, two places per room: the twin bedrooms open onto one hall whose
    doors repeat every 6.6 m, and a robot in bedroom_b drove bedroom_a's two routes to the same
    hall place, arrived both times and ended sure of bedroom_a, 0.985, in 4 of 5 kidnappings;
    the rival's check, where its room has a route, can tell the other way). Likewise after a
    check that did not arrive (on world seed 14, each of the 10 robots in office_b spent its
    first two of four drives on office_a's routes)."""
    top_p = belief.top[1]
    likely = [(room, p) for room, p in belief.ranked() if p >= LIKELY_SHARE * top_p]
    return [room for room, _ in sorted(likely, key=lambda rp: checked.get(rp[0], 0))]


def likely_twin(
    belief: RoomBelief, room: str, lookalikes: Mapping[str, frozenset[str]]
) -> str | None:
    """The most likely of ``room``'s look-alikes (at least :data:`LIKELY_SHARE` of the top
    room's probability), or None."""
    twins = lookalikes.get(room, frozenset())
    top_p = belief.top[1]
    return next(
        (name for name, p in belief.ranked() if name in twins and p >= LIKELY_SHARE * top_p), None
    )


def route_to_check(
    localizer: Localizer,
    belief: RoomBelief,
    observation: Observation,
    tried: set[int],
    checked: Mapping[str, int],
    params: RouteCheckParams,
    avoid: Collection[str] = (),
) -> tuple[Place, Route] | None:
    """A place to check a likely room from, and its recorded route out of the room to a room
    that has no look-alike and is not in ``avoid`` (room names; the route's first leg: a check
    that goes on beyond a hall, :func:`~localizer.route_checks.check_route`, is not held to
    it). The likely rooms are taken in :func:`rooms_to_check`'s order (``checked``: checks
    per room so far), those checked as often as each other first by a route that ends in a
    room their look-alikes do not open onto (:func:`~localizer.routes.shared_rooms`), then by
    any; in each, the places with a route and a heading,
    not tried yet, from the one the latest frame matched best. None if there is none. A room
    whose look-alike has a shorter route beyond is checked by its shortest route, into the
    hall too: where the pair's two checks disagree, the one beyond tells, and the hall check
    agrees with it (76 of 77 such pairs right, docs/results.md); a longer route drifts more
    (world seed 31's building: with the legs joined, office_a's 12 m route to the kitchen
    arrived from office_a in 5 of 10 first checks; its 3 m route into the corridor, before,
    in 10 of the 10 that started). Once the look-alike has been checked, the room takes that
    shortest route in its turn, before less likely rooms' routes (world seed 103's building,
    one place per room: after office_b's check missed, a robot in office_a checked the
    corridor, at 0.09, before office_a, at 0.75; 6 of 20 kidnappings ended ambiguous at the
    drive limit so, none in this order)."""
    counts = {item.place_id: item.spread_inliers for item in observation.evidence.places}
    graph, places = localizer.map.legs, localizer.map.places
    # a route into a look-alike room ends at its twin's spot in the twin's twin: it must end
    # in a room that has none (in the house, bathroom_b and bedroom_b are a copy of the pair
    # bathroom_a and bedroom_a: a route between the two ends alike in both)
    leave = {name for name, partners in localizer.lookalikes.items() if partners} | set(avoid)
    doors = localizer.doors
    rooms = rooms_to_check(belief, checked)

    @functools.cache
    def beyond_m(room: str) -> float:
        route = route_beyond(graph, places, room, localizer.lookalikes, doors, params.route_max_m)
        return math.inf if route is None else route.length_m

    for _, tier in itertools.groupby(rooms, key=lambda room: checked.get(room, 0)):
        starts = {
            room: sorted(
                (
                    place
                    for place in places
                    if place.room == room
                    and place.id in graph
                    and place.heading_deg is not None
                    and place.id not in tried
                ),
                key=lambda q: (-counts.get(q.id, 0.0), q.id),
            )
            for room in tier
        }
        for strict in (True, False):
            for room, room_starts in starts.items():
                leave_room = leave | {room}
                if strict:
                    twins = localizer.lookalikes.get(room, frozenset())
                    if any(beyond_m(twin) < beyond_m(room) for twin in twins):
                        if not any(checked.get(twin) for twin in twins):
                            continue  # the twin's route beyond tells for the pair: any route here
                    else:
                        leave_room |= shared_rooms(doors, room, twins)
                for place in room_starts:
                    route = route_out(graph, places, place.id, leave_room, params.route_max_m)
                    if route is not None:
                        return place, route
    return None
