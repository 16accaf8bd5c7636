"""Scoring single-shot localization honestly: five outcomes, lost never right, unknown rooms."""

import json

import pytest

from toploc.evaluation.localization import (
    LOST_COLUMN,
    OUTCOMES,
    QueryOutcome,
    format_confusion,
    outcome_of,
    score_localization,
)
from toploc.evaluation.localization_report import format_outcomes, format_per_room

CONFUSION = {"hall": {"hall": 2, "kitchen": 0}, "kitchen": {"hall": 1, "kitchen": 1}}
MAP_ROOMS = ("hall", "kitchen")
OLD_KEYS = {
    "n",
    "top1",
    "ambiguous_rate",
    "per_room",
    "confusion",
    "ms_median",
    "ms_p95",
    "stage_ms_median",
}


def outcome(
    true_room: str, predicted: str, state: str = "localized", ms: float = 10.0, p: float = 0.9
) -> QueryOutcome:
    return QueryOutcome("img.png", true_room, predicted, p, state, {"extraction": ms, "other": 1.0})


def one_of_each() -> list[QueryOutcome]:
    """Right localized, right ambiguous, wrong localized, wrong ambiguous, lost (in order)."""
    return [
        outcome("kitchen", "kitchen"),
        outcome("kitchen", "kitchen", "ambiguous"),
        outcome("hall", "kitchen"),
        outcome("hall", "kitchen", "ambiguous"),
        outcome("hall", "hall", "lost", p=0.5),
    ]


def test_top1_ambiguity_and_confusion():
    score = score_localization(
        [
            outcome("kitchen", "kitchen"),
            outcome("kitchen", "hall", "ambiguous"),
            outcome("hall", "hall", "ambiguous"),
            outcome("hall", "hall"),
        ],
        MAP_ROOMS,
    )
    assert score.n == 4
    assert score.top1 == 0.75
    assert score.ambiguous_rate == 0.5
    assert score.confusion == CONFUSION
    assert score.per_room["kitchen"] == {"n": 2, "top1": 0.5, "ambiguous_rate": 0.5}


def test_a_lost_answer_is_never_right_even_when_its_top_room_is_the_true_one():
    score = score_localization([outcome("hall", "hall", "lost", p=0.5)], MAP_ROOMS)
    assert score.top1 == 0.0
    assert score.per_room["hall"]["top1"] == 0.0
    assert score.outcomes["lost"] == 1
    assert score.answer_rate == 0.0
    assert score.top1_answered is None
    assert score.confusion == {"hall": {"hall": 0, LOST_COLUMN: 1}}


def test_each_outcome_is_counted_once():
    score = score_localization(one_of_each(), MAP_ROOMS)
    assert [outcome_of(q, MAP_ROOMS) for q in one_of_each()] == list(OUTCOMES)
    assert score.outcomes == dict.fromkeys(OUTCOMES, 1)
    assert score.rates == dict.fromkeys(OUTCOMES, 0.2)
    assert score.top1 == pytest.approx(0.4)
    assert score.answer_rate == pytest.approx(0.8)
    assert score.top1_answered == pytest.approx(0.5)
    hall = score.per_room_outcomes["hall"]
    assert hall.in_map
    assert hall.counts == {**dict.fromkeys(OUTCOMES, 0), **dict.fromkeys(OUTCOMES[2:], 1)}


def test_a_room_the_map_lacks_is_right_only_when_lost():
    queries = [
        outcome("attic", "attic"),  # even naming it cannot be right: the map has no attic
        outcome("attic", "hall"),
        outcome("attic", "hall", "ambiguous"),
        outcome("attic", "hall", "lost", p=0.5),
        outcome("hall", "hall"),
    ]
    score = score_localization(queries, MAP_ROOMS)
    assert score.outcomes["wrong_localized"] == 2
    assert score.outcomes["wrong_ambiguous"] == 1
    assert score.outcomes["lost"] == 1
    assert score.top1 == pytest.approx(0.2)
    unknown = score.unknown_room
    assert (unknown.n, unknown.lost, unknown.ambiguous, unknown.localized) == (4, 1, 1, 2)
    assert unknown.rooms == ("attic",)
    assert not score.per_room_outcomes["attic"].in_map
    assert "attic (not in map)" in format_per_room(score)


def test_homing_cannot_end_a_one_shot_query():
    with pytest.raises(ValueError, match="state 'homing'"):
        score_localization([outcome("hall", "hall", "homing")], MAP_ROOMS)


def test_a_stated_probability_outside_0_1_is_refused():
    with pytest.raises(ValueError, match=r"top probability must be in 0\.\.1, got 1\.5"):
        outcome("hall", "hall", p=1.5)


def test_timing_percentiles_are_over_the_total_per_query():
    score = score_localization([outcome("a", "a", ms=float(ms)) for ms in range(100)], ("a",))
    assert score.ms_median == pytest.approx(50.5)
    assert score.ms_p95 == pytest.approx(95.05)
    assert score.stage_ms_median == {"extraction": 49.5, "other": 1.0}


def test_the_json_keeps_the_old_keys_and_adds_the_outcomes():
    record = json.loads(json.dumps(score_localization(one_of_each(), MAP_ROOMS).to_json()))
    assert set(record) >= OLD_KEYS
    assert record["top1"] == pytest.approx(0.4)
    assert record["outcomes"] == dict.fromkeys(OUTCOMES, 1)
    assert set(record["rates"]) == set(OUTCOMES)
    assert record["top1_answered"] == pytest.approx(0.5)
    assert record["answer_rate"] == pytest.approx(0.8)
    assert record["unknown_room"] == {
        "n": 0,
        "lost": 0,
        "ambiguous": 0,
        "localized": 0,
        "rooms": [],
    }
    assert record["per_room_outcomes"]["hall"]["rates"]["lost"] == pytest.approx(1 / 3)
    bins = record["calibration"]["bins"]
    assert [b["n"] for b in bins] == [0, 1, 0, 4, 0]  # lost at 0.5, the rest at 0.9
    assert record["calibration"]["brier"] == pytest.approx((0.5**2 + 2 * 0.1**2 + 2 * 0.9**2) / 5)


def test_the_report_leads_with_the_five_outcomes():
    lines = format_outcomes(score_localization(one_of_each(), MAP_ROOMS)).splitlines()
    labels = ["right, localized", "right, ambiguous", "wrong, localized", "wrong, ambiguous"]
    for label, line in zip([*labels, "lost"], lines[1:6], strict=True):
        assert line.startswith(label)
        assert line.split("<-")[0].split()[-2:] == ["1", "20.0%"]
    assert lines[3].endswith("<- confidently wrong")
    assert "top-1 room 40.0%" in lines[6]


def test_no_queries_is_an_error():
    with pytest.raises(ValueError, match="no queries"):
        score_localization([], MAP_ROOMS)


def test_the_confusion_table_has_a_row_per_true_room():
    text = format_confusion(CONFUSION)
    assert text.splitlines()[1].split() == ["hall", "2", "0"]


def test_a_confusion_too_wide_for_a_table_lists_what_each_room_was_taken_for():
    rooms = [f"brown_photostudio_{i:02d}" for i in range(8)]
    confusion = {t: {p: int(t == p) + 2 * (p == rooms[0]) for p in rooms} for t in rooms}
    lines = format_confusion(confusion, max_width=120).splitlines()
    assert len(lines) == 1 + len(rooms)
    assert lines[2] == "  brown_photostudio_01: brown_photostudio_00 (2), brown_photostudio_01 (1)"
    assert max(len(line) for line in lines) <= 120


def test_per_room_columns_stay_aligned_with_long_room_names():
    long_room = "sepulchral_chapel_rotunda"
    score = score_localization(
        [outcome("hall", "hall", "localized"), outcome(long_room, "hall", "lost")], MAP_ROOMS
    )
    lines = format_per_room(score).splitlines()
    assert len({len(line) for line in lines}) == 1, lines  # every column ends where its header does


def mapped_and_unknown() -> list[QueryOutcome]:
    """Two queries from rooms of the map (one right, one wrong) and three from an attic the map
    lacks, all rightly lost."""
    return [
        outcome("kitchen", "kitchen"),
        outcome("hall", "kitchen"),
        *(outcome("attic", "hall", "lost", p=0.5) for _ in range(3)),
    ]


def test_the_headline_scores_the_queries_from_rooms_of_the_map():
    score = score_localization(mapped_and_unknown(), MAP_ROOMS)
    known = score.known_room
    assert (known.n, known.top1, known.answer_rate) == (2, 0.5, 1.0)
    assert known.outcomes["right_localized"] == known.outcomes["wrong_localized"] == 1
    lines = format_outcomes(score).splitlines()
    assert "the 2 queries from rooms of the map" in lines[0]
    assert lines[1].split()[-2:] == ["1", "50.0%"]  # right, localized: 1 of the 2
    assert lines[6].startswith("n 2: top-1 room 50.0%")


def test_the_queries_from_rooms_the_map_lacks_have_a_line_of_their_own():
    last = format_outcomes(score_localization(mapped_and_unknown(), MAP_ROOMS)).splitlines()[-1]
    assert last.startswith("rooms not in the map (attic): n 3, lost 3 (right)")
    assert "localized 0 (confidently wrong" in last


def test_the_json_adds_the_known_room_score_and_keeps_top1_over_every_query():
    record = json.loads(json.dumps(score_localization(mapped_and_unknown(), MAP_ROOMS).to_json()))
    assert record["top1"] == pytest.approx(0.2)  # as before: 1 right of all 5
    assert record["known_room"]["top1"] == pytest.approx(0.5)
    assert record["known_room"]["n"] == 2 and record["unknown_room"]["lost"] == 3
