"""Checking a likely room by a recorded route: the parameters, which rooms to check first and
what a room's checks have told (the drives themselves: tests/toploc/test_recorded_maps.py)."""

from __future__ import annotations

import numpy as np
import pytest

from localizer.belief import RoomBelief
from localizer.route_checks import RouteCheck, RouteCheckParams, rooms_to_check, told_outcomes


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
