"""Statistics of homing errors (eqs. 5.5-5.6, figure 5.4)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from homing.alv import HomingError
from homing.thesis.evaluation import (
    FAILED_ERROR_DEG,
    errors_by_distance,
    homing_statistics,
    pair_errors_deg,
    true_home_direction_rad,
)


def test_statistics_against_a_naive_double_loop() -> None:
    rng = np.random.default_rng(3)
    ids = [f"p{i}" for i in range(6)]
    here, home, errors = [], [], []
    for i in ids:
        for j in ids:
            if i != j:
                here.append(i)
                home.append(j)
                errors.append(rng.uniform(0, 180))
    stats = homing_statistics(np.array(errors), np.array(here), np.array(home))
    n = len(ids)
    naive_score = 1 - sum(errors) / (180 * n * (n - 1))  # eq. 5.6 as written
    per_home = {h: np.mean([e for e, hh in zip(errors, home, strict=True) if hh == h]) for h in ids}
    assert stats.n == n and stats.n_pairs == n * (n - 1) and stats.n_failed == 0
    assert stats.score == pytest.approx(naive_score)
    assert stats.mean_deg == pytest.approx(np.mean(errors))
    assert stats.median_deg == pytest.approx(np.median(errors))
    assert stats.std_deg == pytest.approx(np.std(errors, ddof=1))
    assert stats.best_home == min(per_home, key=per_home.get)
    assert stats.under_90 == pytest.approx(np.mean(np.array(errors) <= 90))
    assert stats.under_10 == pytest.approx(np.mean(np.array(errors) <= 10))
    record = stats.to_json(detector="sift", method="thesis")
    expected = {"detector", "method", "n", "mean_deg", "median_deg", "std_deg", "score"}
    assert expected | {"best_home", "under_90", "under_10"} <= set(record)


def test_failed_pairs_are_charged_and_counted() -> None:
    stats = homing_statistics(np.array([0.0, np.nan]), np.array(["a", "b"]), np.array(["b", "a"]))
    assert stats.n_failed == 1
    assert stats.mean_deg == pytest.approx(FAILED_ERROR_DEG / 2)
    assert stats.best_home == "b"


@pytest.mark.parametrize(
    ("errors", "here", "home", "match"),
    [
        ([], [], [], "at least one"),
        ([1.0, 2.0], ["a"], ["b", "a"], "2 errors but 1 current"),
        ([190.0], ["a"], ["b"], r"\[0, 180\]"),
        ([-1.0], ["a"], ["b"], r"\[0, 180\]"),
    ],
)
def test_bad_statistics_input(errors, here, home, match) -> None:
    with pytest.raises(HomingError, match=match):
        homing_statistics(np.array(errors), np.array(here), np.array(home))


def test_pair_error_uses_the_current_heading() -> None:
    # Home is north (+y) of here; the robot faces west (heading 90 deg... CCW from x: north is
    # 90 deg): facing north, the home is straight ahead (0 rad in the robot frame).
    truth = true_home_direction_rad(np.array([0.0, 0.0]), np.array([0.0, 2.0]))
    assert float(pair_errors_deg(0.0, math.pi / 2, truth)) == pytest.approx(0.0)
    assert float(pair_errors_deg(math.pi / 2, math.pi / 2, truth)) == pytest.approx(90.0)


def test_errors_by_distance_bins() -> None:
    bins = errors_by_distance(np.array([0.2, 0.4, 1.1, 1.2]), np.array([10.0, 20.0, 30.0, np.nan]))
    assert [(b.low_m, b.n) for b in bins] == [(0.0, 2), (1.0, 2)]
    assert bins[0].mean_deg == pytest.approx(15.0)
    assert bins[1].mean_deg == pytest.approx((30.0 + FAILED_ERROR_DEG) / 2)
    with pytest.raises(HomingError, match="bin width"):
        errors_by_distance(np.array([1.0]), np.array([1.0]), 0.0)
    with pytest.raises(HomingError, match="equal 1-D"):
        errors_by_distance(np.array([1.0, 2.0]), np.array([1.0]))
