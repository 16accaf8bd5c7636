"""Scoring single-shot localization."""

import pytest

from toploc.evaluation.localization import QueryOutcome, format_confusion, score_localization

CONFUSION = {"hall": {"hall": 2, "kitchen": 0}, "kitchen": {"hall": 1, "kitchen": 1}}


def outcome(true_room: str, predicted: str, state: str = "localized", ms: float = 10.0):
    return QueryOutcome("img.png", true_room, predicted, state, {"extraction": ms, "other": 1.0})


def test_top1_ambiguity_and_confusion():
    score = score_localization(
        [
            outcome("kitchen", "kitchen"),
            outcome("kitchen", "hall", "ambiguous"),
            outcome("hall", "hall", "ambiguous"),
            outcome("hall", "hall"),
        ]
    )
    assert score.n == 4
    assert score.top1 == 0.75
    assert score.ambiguous_rate == 0.5
    assert score.confusion == CONFUSION
    assert score.per_room["kitchen"] == {"n": 2, "top1": 0.5, "ambiguous_rate": 0.5}


def test_timing_percentiles_are_over_the_total_per_query():
    score = score_localization([outcome("a", "a", ms=float(ms)) for ms in range(100)])
    assert score.ms_median == pytest.approx(50.5)
    assert score.ms_p95 == pytest.approx(95.05)
    assert score.stage_ms_median == {"extraction": 49.5, "other": 1.0}


def test_the_json_has_the_issue_keys():
    keys = set(score_localization([outcome("a", "a")]).to_json())
    assert {"n", "top1", "ambiguous_rate", "per_room", "confusion", "ms_median", "ms_p95"} <= keys


def test_no_queries_is_an_error():
    with pytest.raises(ValueError, match="no queries"):
        score_localization([])


def test_the_confusion_table_has_a_row_per_true_room():
    text = format_confusion(CONFUSION)
    assert text.splitlines()[1].split() == ["hall", "2", "0"]
