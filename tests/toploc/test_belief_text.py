"""The belief as the command line prints it (``toploc belief``, ``localize``, ``demo``)."""

from __future__ import annotations

from typing import Any

from toploc.commands.belief_text import format_belief, state_line
from toploc.commands.demo import verdict


def belief(state: str, rooms: dict[str, float], best: dict[str, Any] | None = None) -> dict:
    top = max(rooms, key=rooms.__getitem__)
    return {
        "rooms": rooms,
        "state": state,
        "entropy_bits": 0.0,
        "top": {"room": top, "probability": rooms[top]},
        "best_place": best,
        "stamp": 12.5,
    }


LOST = belief(
    "lost", {"office_b": 1.0, "office_a": 0.0}, {"place_id": 7, "room": "office_b", "inliers": 12}
)


def test_a_lost_belief_names_no_room_as_its_answer():
    assert state_line(LOST) == "lost: no room of the map matches (best office_b, 12 inliers)"
    text = format_belief(LOST)
    assert "1.000" not in text and "#" not in text
    assert text.splitlines()[0] == state_line(LOST)


def test_a_localized_belief_leads_with_its_room():
    localized = belief("localized", {"office_a": 0.003, "office_b": 0.997})
    assert state_line(localized) == "localized in office_b (p 0.997)"
    lines = format_belief(localized).splitlines()
    assert lines[0] == "localized in office_b (p 0.997)"
    assert lines[-2].split()[:2] == ["office_b", "0.997"]  # rooms from the most likely


def test_an_ambiguous_belief_lists_its_top_rooms():
    rooms = {"office_a": 0.37, "office_b": 0.62, "kitchen": 0.01, "seminar": 0.0}
    assert state_line(belief("ambiguous", rooms)) == (
        "ambiguous: office_b 0.620, office_a 0.370, kitchen 0.010"
    )
    assert len(format_belief(belief("ambiguous", rooms), top=2).splitlines()) == 3 + 2


def test_the_demo_counts_a_lost_final_belief_as_wrong_whatever_room_is_first():
    assert verdict(LOST, "office_b") == "WRONG"
    assert verdict(belief("localized", {"office_b": 0.97, "office_a": 0.03}), "office_b") == "right"


def test_an_active_reply_says_how_many_drives_and_why_it_ended():
    settled = belief("localized", {"office_a": 0.03, "office_b": 0.97})
    settled["active"] = {"drives": 2, "distance_m": 1.894, "ended": "settled"}
    assert format_belief(settled).splitlines()[3] == "active: 2 drives, 1.89 m; settled"


def test_a_belief_sure_by_its_odds_that_waits_says_why():
    waiting = belief("ambiguous", {"circus_arena": 1.0, "vestibule": 0.0})
    waiting["partly_seen"] = {"room": "circus_arena", "horizon_share": 0.44, "needed_share": 0.6}
    line = format_belief(waiting).splitlines()[3]
    assert line.startswith("waits: circus_arena seen on 44% of the horizon, 60% needed")
    homing = {**waiting, "state": "homing"}  # driving to look: the line would be stale
    assert not any(text.startswith("waits:") for text in format_belief(homing).splitlines())


def test_twins_with_no_telling_place_get_a_hint_of_what_to_record():
    twins = belief("ambiguous", {"office_a": 0.5, "office_b": 0.5, "kitchen": 0.0})
    twins["active"] = {"drives": 0, "distance_m": 0.0, "ended": "no-telling-place"}
    lines = format_belief(twins).splitlines()
    assert lines[3] == "active: 0 drives, 0.00 m; no place of the map tells office_a from office_b"
    assert "toploc map info" in lines[4]


def test_an_ending_this_version_does_not_know_is_shown_as_it_came():
    odd = belief("ambiguous", {"office_a": 0.5, "office_b": 0.5})
    odd["active"] = {"drives": 1, "distance_m": 0.5, "ended": "battery {low}"}
    assert format_belief(odd).splitlines()[3] == "active: 1 drive, 0.50 m; battery {low}"
