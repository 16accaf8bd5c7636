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
