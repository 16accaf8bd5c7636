"""``toploc map info``'s advice on look-alike rooms, from the map's records alone."""

from __future__ import annotations

from pathlib import Path

from localizer.likelihood import RatioLikelihood
from mapdb.records import Leg, MapInfo, Place, RoomSummary
from toploc.commands.map_text import format_info, lookalike_lines

DOORS = (("hall", "twin_a"), ("hall", "twin_b"), ("hall", "living"))
TWINS = RatioLikelihood(lookalikes=(("twin_a", "twin_b"),))


def drive_to_living(living_x_m: float, living_places: int = 2) -> list[Place]:
    """One drive: the hall's place, twin_a's, twin_b's (along the hall, 0.5 m off its wall),
    then back out of twin_b along the hall and through a door into the living room, whose
    first place stands at ``living_x_m`` (a second 1 m further in, if ``living_places`` is
    2): the only recorded drive on beyond the hall."""
    places = [
        Place(1, "hall", 0.0, 0.0, 0.0),
        Place(2, "twin_a", 2.0, 2.0, 0.0, leg=Leg(1)),
        Place(3, "twin_b", 8.0, 2.0, 0.0, leg=Leg(2, ((2.0, 0.5), (8.0, 0.5)))),
        Place(4, "living", living_x_m, -3.5, 0.0, leg=Leg(3, ((8.0, 0.5), (living_x_m, 0.5)))),
    ]
    if living_places == 2:
        places.append(Place(5, "living", living_x_m, -4.5, 0.0, leg=Leg(4)))
    return places


def test_twins_with_a_drive_on_beyond_the_hall_are_told_apart_by_it():
    lines = lookalike_lines(TWINS, drive_to_living(15.0), DOORS)  # 1.5 + 7 + 4 m from twin_b
    assert any("twin_a ~ twin_b" in line and "recorded drive out" in line for line in lines)
    assert not any("end only in hall" in line or "one place" in line for line in lines)


def test_a_drive_beyond_longer_than_a_check_drives_asks_for_another():
    lines = lookalike_lines(TWINS, drive_to_living(18.0), DOORS)  # 15.5 m: over ROUTE_MAX_M
    assert not any("recorded drive out" in line for line in lines)
    [advice] = [line for line in lines if "end only in hall" in line]
    assert "twin_a ~ twin_b" in advice and "Record the drive on" in advice


def test_twins_whose_drives_beyond_end_in_a_room_of_one_place_are_not_said_told_apart():
    """A room of one place may have a look-alike the map cannot see (world seed 55's house, one
    place per room: each bathroom's only drive beyond ended in the bedroom beside it, and the
    bedrooms, copies, were not known as look-alikes; the drives arrived from both bathrooms)."""
    lines = lookalike_lines(TWINS, drive_to_living(15.0, living_places=1), DOORS)
    assert not any("recorded drive out" in line for line in lines)
    [advice] = [line for line in lines if "known from one place" in line]
    assert "twin_a ~ twin_b" in advice and "Record a second place in living" in advice


def test_places_stored_without_keypoint_sizes_are_counted_with_what_to_do():
    info = MapInfo(Path("old.db"), 5, 1000, [RoomSummary(1, "hall", 2)], [], {"sift": 2})
    assert "keypoints' sizes" not in format_info(info)
    old = MapInfo(
        Path("old.db"), 5, 1000, [RoomSummary(1, "hall", 2)], [], {"sift": 2},
        fingerprints_without_sizes=2,
    )  # fmt: skip
    [line] = [line for line in format_info(old).splitlines() if "keypoints' sizes" in line]
    assert line.strip().startswith("2 stored without") and "record them again" in line
