"""The calibrated likelihood: a density ratio of same-room and other-room inlier counts, fitted
on leave-one-out evidence; rooms do not cap a frame, and chance counts stay lost."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from localizer.likelihood import RatioLikelihood
from localizer.likelihood_fit import (
    CalibrationSamples,
    fit_ratio_likelihood,
    largest_without_each,
    medians_without_each,
)


def samples(rng: np.random.Generator, n_queries: int, n_rooms: int) -> CalibrationSamples:
    """Same-room counts around 25, other-room counts around 6 (Poisson), like a bare house."""
    queries = []
    for q in range(n_queries):
        own = f"r{q % n_rooms}"
        best = {f"r{r}": float(rng.poisson(6)) for r in range(n_rooms)}
        best[own] = float(rng.poisson(25))
        queries.append((own, best))
    return CalibrationSamples.from_queries(queries, {f"r{r}": 3 for r in range(n_rooms)})


@given(st.lists(st.integers(0, 50).map(float), max_size=12))
def test_medians_without_each_match_a_median_per_left_out_entry(values: list[float]) -> None:
    naive = [
        float(np.median(values[:i] + values[i + 1 :])) if len(values) > 1 else 0.0
        for i in range(len(values))
    ]
    np.testing.assert_allclose(medians_without_each(values), naive)


@given(st.lists(st.integers(0, 50).map(float), max_size=12))
def test_largest_without_each_match_a_max_per_left_out_entry(values: list[float]) -> None:
    naive = [max(values[:i] + values[i + 1 :], default=0.0) for i in range(len(values))]
    np.testing.assert_array_equal(largest_without_each(values), naive)


def test_samples_split_own_room_and_the_others() -> None:
    queries = [("a", {"a": 30.0, "b": 4.0}), ("b", {"a": 9.0}), ("c", {"a": 2.0, "b": 1.0})]
    got = CalibrationSamples.from_queries(queries, {"a": 2, "b": 2, "c": 1})
    np.testing.assert_array_equal(got.same_room, [30.0, 0.0])  # b's own room got nothing
    np.testing.assert_array_equal(got.other_room, [4.0, 0.0, 9.0, 0.0, 2.0, 1.0])
    np.testing.assert_array_equal(got.max_other, [4.0, 9.0, 2.0])  # c has one place: no same


def test_a_room_seen_through_a_door_is_not_chance() -> None:
    # a hall place: its own room 180, the two bedrooms through their doors 40 and 38, the
    # other rooms 2-5 by chance
    best = {"hall": 180.0, "bed_a": 40.0, "bed_b": 38.0, "kitchen": 3.0, "study": 5.0, "bath": 2.0}
    got = CalibrationSamples.from_queries([("hall", best)], dict.fromkeys(best, 1) | {"hall": 2})
    np.testing.assert_array_equal(got.max_other, [5.0])  # the chance level: the study's
    assert sorted(got.other_room) == [2.0, 3.0, 5.0, 38.0, 40.0]  # all other-room samples


def test_the_fit_separates_same_from_other_rooms() -> None:
    model = fit_ratio_likelihood(samples(np.random.default_rng(0), 60, 6))
    assert model.log_ratio(25) > 2.0  # a typical own-room count is strong evidence
    assert model.log_ratio(6) < -1.0  # a typical chance count argues against the room
    assert np.all(np.diff(model.log_ratio(np.arange(60))) >= 0)  # more inliers never hurt
    assert model.fit["n_same_room"] == 60 and model.fit["n_other_room"] == 300


def top_two_ratio(likelihood: np.ndarray) -> float:
    second, top = np.sort(likelihood)[-2:]
    return float(top / second)


def test_chance_counts_of_a_room_not_in_the_map_are_lost_or_undecided() -> None:
    rng = np.random.default_rng(1)
    model = fit_ratio_likelihood(samples(rng, 60, 6))
    # a query from a seventh room: every room of the map scores by chance only
    unknown = [model.from_room_inliers(rng.poisson(6, size=6).astype(float)) for _ in range(500)]
    # lost below the median chance level: about half of them; the rest undecided
    assert np.mean([np.ptp(lik) == 0 for lik in unknown]) >= 0.5
    assert np.mean([top_two_ratio(lik) >= 10 for lik in unknown]) <= 0.02  # rarely one room
    # a query from a room of the map: one frame usually decides
    known = []
    for _ in range(500):
        counts = rng.poisson(6, size=6).astype(float)
        counts[0] = rng.poisson(25)
        known.append(model.from_room_inliers(counts))
    assert np.mean([top_two_ratio(lik) >= 10 and lik.argmax() == 0 for lik in known]) >= 0.85


def with_lead(n_rooms: int, lead: float) -> np.ndarray:
    counts = np.full(n_rooms, 7.0)
    counts[0] = lead
    return counts


def test_the_number_of_rooms_does_not_cap_one_frame() -> None:
    # (a softmax over rooms saturated below 1 - floor + floor / N: 29 against 7 gave 25 %)
    model = RatioLikelihood()
    for n_rooms in (2, 15, 60):
        weak, strong = with_lead(n_rooms, 30.0), with_lead(n_rooms, 300.0)
        # the confidence grows with the lead, whatever the number of rooms
        assert model.from_room_inliers(strong)[0] > max(0.99, model.from_room_inliers(weak)[0])


def test_without_same_room_samples_the_ratio_stays_and_chance_is_measured() -> None:
    one_place_each = CalibrationSamples.from_queries(
        [("a", {"b": 15.0, "c": 9.0}), ("b", {"a": 12.0, "c": 8.0}), ("c", {"a": 2.0})],
        {"a": 1, "b": 1, "c": 1},
    )
    model, prior = fit_ratio_likelihood(one_place_each), RatioLikelihood()
    assert (model.intercept, model.slope, model.per_inlier) == (
        prior.intercept,
        prior.slope,
        prior.per_inlier,
    )
    assert model.min_inliers == 13  # the median of the best other rooms (2, 12, 15), plus one


def test_json_round_trip_and_bad_input() -> None:
    model = fit_ratio_likelihood(samples(np.random.default_rng(2), 30, 4))
    assert RatioLikelihood.from_json(model.to_json()) == model
    with pytest.raises(ValueError, match="not a ratio likelihood"):
        RatioLikelihood.from_json({"schema": 1, "model": "softmax"})
    with pytest.raises(ValueError, match="bad stored likelihood"):
        RatioLikelihood.from_json({"schema": 1, "model": "ratio", "intercept": "x"})
    with pytest.raises(ValueError, match="slope and per_inlier must be >= 0"):
        RatioLikelihood(slope=-1.0)
    with pytest.raises(ValueError, match="room_inliers must be finite"):
        model.from_room_inliers(np.array([1.0, np.nan]))


def test_chance_that_lifts_every_room_stays_the_chance_level() -> None:
    # shared texture: every other room 22-40 against its own 80-150; none stands out
    rng = np.random.default_rng(4)
    rooms = [f"r{r}" for r in range(6)]
    queries = []
    for q in range(60):
        own = rooms[q % 6]
        best = {room: float(rng.integers(22, 41)) for room in rooms}
        best[own] = float(rng.integers(80, 151))
        queries.append((own, best))
    samples = CalibrationSamples.from_queries(queries, dict.fromkeys(rooms, 3))
    assert len(samples.max_other) == 60
    assert fit_ratio_likelihood(samples).min_inliers > 30
