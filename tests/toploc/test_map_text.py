"""``toploc map info``'s advice on look-alike rooms, from the map's records alone."""

from __future__ import annotations

from localizer.likelihood import RatioLikelihood
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


def test_twins_with_a_drive_on_beyond_the_hall_are_told_apart_by_it():
    lines = lookalike_lines(TWINS, drive_to_living(15.0), DOORS)  # 1.5 + 7 + 4 m from twin_b
    assert any("twin_a ~ twin_b" in line and "recorded drive out" in line for line in lines)
    assert not any("end only in hall" in line for line in lines)


def test_a_drive_beyond_longer_than_a_check_drives_asks_for_another():
    lines = lookalike_lines(TWINS, drive_to_living(18.0), DOORS)  # 15.5 m: over ROUTE_MAX_M
    assert not any("recorded drive out" in line for line in lines)
    [advice] = [line for line in lines if "end only in hall" in line]
    assert "twin_a ~ twin_b" in advice and "Record the drive on" in advice
