"""Checking a likely room by a recorded route: the parameters (route_checks), which rooms to
check first and what a room's checks have told (route_choice; the drives themselves:
tests/toploc/test_recorded_maps.py)."""

from __future__ import annotations

import numpy as np
import pytest

from localizer.belief import RoomBelief
from localizer.route_checks import RouteCheck, RouteCheckParams
from localizer.route_choice import (
    repeating_ends,
    rooms_to_check,
    starts_to_check_again,
    telling_checks,
    told_outcomes,
)


def test_route_check_params_refuse_route_rates_that_tell_nothing():
    with pytest.raises(ValueError, match="route_false_rate < route_hit_rate"):
        RouteCheckParams(route_hit_rate=0.5, route_false_rate=0.5)


def test_a_room_checked_once_is_checked_after_its_rival_whatever_came_out():
    belief = RoomBelief.from_probabilities(("office_a", "office_b"), np.array([0.6, 0.4]))
    assert rooms_to_check(belief, {}) == ["office_a", "office_b"]
    assert rooms_to_check(belief, {"office_a": 1}) == ["office_b", "office_a"]


def check(room: str, confirmed: bool, back_room: str | None, afresh: bool = False) -> RouteCheck:
    return RouteCheck(room, 1, 2, confirmed, 10.0, back_room=back_room, afresh=afresh)


def test_a_rooms_checks_tell_what_came_back_to_it():
    checks = [check("office_a", False, "office_a"), check("office_b", True, "office_b")]
    assert told_outcomes(checks, "office_a") == {False}
    assert told_outcomes(checks, "office_b") == {True}
    assert told_outcomes([check("office_a", True, None)], "office_a") == frozenset()
    assert told_outcomes([check("office_a", True, "office_b")], "office_a") == frozenset()


def test_checks_before_the_belief_started_afresh_tell_nothing_any_more():
    missed = check("office_b", False, "office_b")
    lost_way = check("office_a", True, None, afresh=True)
    assert told_outcomes([missed, lost_way], "office_b") == frozenset()
    assert told_outcomes([lost_way, missed], "office_b") == {False}


def test_only_likely_rooms_are_checked_by_a_route():
    rooms = ("corridor", "office_a", "office_b")
    belief = RoomBelief.from_probabilities(rooms, np.array([0.005, 0.99, 0.005]))
    assert rooms_to_check(belief, {"office_a": 1}) == ["office_a"]


TWINS = {"bathroom_a": {"bathroom_b"}, "bathroom_b": {"bathroom_a"}}
ROOMS = {1: "hall", 2: "bedroom_a", 3: "bathroom_a", 4: "bedroom_b", 5: "bathroom_b", 6: "living"}


def room_of(place_id: int) -> str:
    return ROOMS[place_id]


def routed(
    room: str, start: int, end: int, confirmed: bool, afresh: bool = False, via: int | None = None
) -> RouteCheck:
    """A check of ``room`` from place ``start`` by a route to ``end`` (on from ``via``), that
    came back to ``room``."""
    return RouteCheck(room, start, end, confirmed, 10.0, back_room=room, afresh=afresh, via=via)


def test_where_both_twins_checks_arrive_their_routes_end_alike():
    # each bathroom's route leads into the bedroom beside it: a copy of the other wing
    checks = [routed("bathroom_a", 3, 2, True), routed("bathroom_b", 5, 4, True)]
    assert repeating_ends(checks, TWINS, room_of) == {"bedroom_a", "bedroom_b"}


def test_routes_end_alike_only_where_both_twins_checks_arrived():
    missed = [routed("bathroom_a", 3, 2, True), routed("bathroom_b", 5, 4, False)]
    assert repeating_ends(missed, TWINS, room_of) == frozenset()
    not_twins = [routed("bathroom_a", 3, 2, True), routed("bedroom_b", 4, 1, True)]
    assert repeating_ends(not_twins, TWINS, room_of) == frozenset()


def test_checks_before_the_belief_started_afresh_show_no_repeating_ends():
    before = routed("bathroom_a", 3, 2, True)
    lost_way = routed("bathroom_b", 5, 4, True, afresh=True)
    assert repeating_ends([before, lost_way], TWINS, room_of) == frozenset()


def test_a_check_that_arrived_by_a_route_ending_elsewhere_does_not_repeat():
    # the false arrival of bathroom_b's check is explained by the bedrooms already
    checks = [
        routed("bathroom_a", 3, 2, True),
        routed("bathroom_b", 5, 4, True),
        routed("bathroom_a", 3, 6, True, via=1),  # into the hall, then on to the living room
    ]
    assert repeating_ends(checks, TWINS, room_of) == {"bedroom_a", "bedroom_b"}


def test_a_check_ends_where_its_first_route_ended_when_it_went_on_beyond():
    assert routed("bathroom_a", 3, 6, True, via=1).first_end == 1
    assert routed("bathroom_a", 3, 2, True).first_end == 2


def test_arrivals_where_routes_end_alike_tell_nothing_but_misses_there_do():
    arrived, missed = routed("bathroom_a", 3, 2, True), routed("bathroom_a", 3, 2, False)
    repeating = {"bedroom_a", "bedroom_b"}
    assert telling_checks([arrived, missed], repeating, room_of) == [missed]
    assert told_outcomes(telling_checks([arrived], repeating, room_of), "bathroom_a") == set()


def test_a_start_is_checked_again_only_if_all_its_checks_ended_where_routes_repeat():
    checks = [
        routed("bathroom_a", 3, 2, True),
        routed("bathroom_b", 5, 4, True),
        routed("bathroom_b", 5, 6, False, via=1),
    ]
    assert starts_to_check_again(checks, {"bedroom_a", "bedroom_b"}, room_of) == {3}
