"""Reliability of the stated top-room probability: reliability bins and the Brier score."""

import itertools

import numpy as np
import pytest

from toploc.evaluation.localization import QueryOutcome, score_localization
from toploc.evaluation.reliability import (
    RELIABILITY_EDGES,
    brier_score,
    reliability,
    reliability_bins,
)

STATED = [0.2, 0.6, 0.6, 0.8, 0.95, 0.995, 1.0, 0.5, 0.99]
RIGHT = [False, True, False, True, True, True, True, False, True]


def test_each_answer_falls_in_the_bin_of_its_stated_probability():
    bins = reliability_bins(STATED, RIGHT)
    assert [(b.low, b.high) for b in bins] == list(itertools.pairwise(RELIABILITY_EDGES))
    assert [b.n for b in bins] == [1, 3, 1, 1, 3]  # 0.5 opens its bin, 0.99 and 1.0 the last
    assert bins[1].mean_stated == pytest.approx((0.6 + 0.6 + 0.5) / 3)
    assert bins[1].fraction_right == pytest.approx(1 / 3)
    assert bins[4].mean_stated == pytest.approx((0.995 + 1.0 + 0.99) / 3)
    assert [b.fraction_right for b in bins] == pytest.approx([0.0, 1 / 3, 1.0, 1.0, 1.0])


def test_an_empty_bin_has_no_mean():
    bins = reliability_bins([0.95], [True])
    assert [b.n for b in bins] == [0, 0, 0, 1, 0]
    assert bins[0].mean_stated is None and bins[0].fraction_right is None


def test_brier_score_by_hand():
    gaps = [0.2, 0.4, 0.6, 0.2, 0.05, 0.005, 0.0, 0.5, 0.01]
    assert brier_score(STATED, RIGHT) == pytest.approx(np.mean(np.square(gaps)))
    assert reliability(STATED, RIGHT).brier == brier_score(STATED, RIGHT)


def test_the_bins_agree_with_a_plain_loop():
    rng = np.random.default_rng(0)
    for _ in range(50):
        stated = rng.choice([0.0, 0.5, 0.7, 0.9, 0.99, 1.0, *rng.random(20)], size=15)
        right = rng.random(15) < stated
        for k, b in enumerate(reliability_bins(stated, right)):
            last = k == len(RELIABILITY_EDGES) - 2
            mine = [
                (p, r)
                for p, r in zip(stated, right, strict=True)
                if b.low <= p < b.high or (last and p == b.high)
            ]
            assert b.n == len(mine)
            if mine:
                assert b.mean_stated == pytest.approx(np.mean([p for p, _ in mine]))
                assert b.fraction_right == pytest.approx(np.mean([r for _, r in mine]))


def test_mismatched_or_out_of_range_input_is_refused():
    with pytest.raises(ValueError, match=r"got shapes \(2,\) and \(1,\)"):
        brier_score([0.5, 0.5], [True])
    with pytest.raises(ValueError, match=r"must be in 0\.\.1, got \[1\.2\]"):
        reliability_bins([1.2], [True])


def test_a_confident_lost_answer_counts_as_not_right_in_the_calibration():
    queries = [
        QueryOutcome("a.png", "hall", "hall", 0.995, "lost", {}),
        QueryOutcome("b.png", "hall", "hall", 0.995, "localized", {}),
    ]
    calibration = score_localization(queries, ("hall",)).calibration
    assert calibration.bins[-1].n == 2
    assert calibration.bins[-1].fraction_right == 0.5
    assert calibration.brier == pytest.approx((0.995**2 + 0.005**2) / 2)
