"""``toploc map info``'s advice on look-alike rooms, from the map's records alone."""

from __future__ import annotations

import re

import pytest

from localizer.likelihood import RatioLikelihood
from localizer.routes import LONG_ROUTE_M
from mapdb.records import Leg, Place
from toploc.commands.map_text import lookalike_lines

DOORS = (("hall", "twin_a"), ("hall", "twin_b"), ("hall", "living"))
TWINS = RatioLikelihood(lookalikes=(("twin_a", "twin_b"),))


def drive_to_living(living_x_m: float) -> list[Place]:
    """One drive: the hall's place, twin_a's, twin_b's (along the hall, 0.5 m off its wall),
    then back out of twin_b along the hall and through a door into the living room, whose
    place stands at ``living_x_m``: the only recorded drive on beyond the hall."""
    return [
        Place(1, "hall", 0.0, 0.0, 0.0),
        Place(2, "twin_a", 2.0, 2.0, 0.0, leg=Leg(1)),
        Place(3, "twin_b", 8.0, 2.0, 0.0, leg=Leg(2, ((2.0, 0.5), (8.0, 0.5)))),
        Place(4, "living", living_x_m, -3.5, 0.0, leg=Leg(3, ((8.0, 0.5), (living_x_m, 0.5)))),
    ]


def test_twins_whose_only_drive_beyond_is_long_are_asked_for_a_shorter_one():
    lines = lookalike_lines(TWINS, drive_to_living(15.0), DOORS)  # about 1.5 + 7 + 4 m
    assert any("each has a recorded drive out" in line for line in lines)
    [advice] = [line for line in lines if "shortest recorded drive" in line]
    said = re.search(r"to a room beyond is ([0-9.]+) m \(from twin_b\)", advice)
    assert "twin_a ~ twin_b" in advice and said and LONG_ROUTE_M < float(said[1]) < 13.0
    assert f"over {LONG_ROUTE_M:g} m" in advice and "Record a shorter drive" in advice


@pytest.mark.parametrize("living_x_m", [10.0, 12.0])  # 8.5 m, 10.5 m
def test_twins_with_a_short_drive_beyond_get_no_advice_on_its_length(living_x_m):
    lines = lookalike_lines(TWINS, drive_to_living(living_x_m), DOORS)
    assert any("each has a recorded drive out" in line for line in lines)
    assert not any("shortest recorded drive" in line for line in lines)
