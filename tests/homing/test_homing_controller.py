"""toploc's simulation controller (``--method best``): matched home vectors and robustness."""

from dataclasses import replace

import numpy as np
import pytest

from homing.thesis.controller import GAIN_MIN, best_controller, matched_home_vectors
from homing.thesis.simulation import (
    Outcome,
    RunState,
    SimulationParams,
    Views,
    project,
    sample_features,
    simulate_runs,
    thesis_controller,
)

B3 = SimulationParams(start_xy_m=(-2.0, -2.0), goal_xy_m=(2.0, 2.0))


def _views(params, runs, seed, here_xy, goal_xy):
    rng = np.random.default_rng(seed)
    features = sample_features(params, runs, rng)
    goal = project(features, np.tile(goal_xy, (runs, 1)), params, rng, with_bearings=True)
    here = project(features, here_xy, params, rng, with_bearings=True)
    return goal, here


@pytest.mark.parametrize("world", [1, 2, 3, 4])
def test_matched_home_vectors_point_home_even_with_few_matches(world):
    """Each matched term is a descent direction of the distance to the goal (it is convex)."""
    runs = 200
    params = replace(B3, world=world, removed_features=990)  # ~10 seen, 0-2 matched
    here_xy = np.random.default_rng(world).uniform(-2.4, 2.4, (runs, 2))
    goal_xy = np.array(params.goal_xy_m)
    goal, here = _views(params, runs, world, here_xy, goal_xy)
    home, _, matches = matched_home_vectors(goal, here, params.features, np.zeros(runs), True)
    some = matches > 0
    assert some.sum() > 10
    toward_goal = goal_xy - here_xy[some]
    assert np.all((home[some] * toward_goal).sum(axis=1) >= -1e-12)
    assert np.all(np.isnan(home[~some]))


def test_fake_features_never_enter_the_home_vector():
    runs, params = 8, replace(B3, fake_features=0)
    here_xy = np.tile([-1.0, 0.5], (runs, 1))
    goal, here = _views(params, runs, 3, here_xy, np.array(params.goal_xy_m))
    fake_bearings = np.random.default_rng(4).uniform(-np.pi, np.pi, (runs, 500))
    faked = Views(
        np.concatenate([here.bearing_rad, fake_bearings], axis=1),
        np.concatenate([here.visible, np.ones((runs, 500), dtype=bool)], axis=1),
        here.alv,
        here.count + 500,
        here.rotation_rad,
    )
    clean, _, _ = matched_home_vectors(goal, here, params.features, np.zeros(runs))
    noisy, _, _ = matched_home_vectors(goal, faked, params.features, np.zeros(runs))
    np.testing.assert_allclose(noisy, clean)


def test_a_view_that_matches_nothing_is_not_acted_on():
    runs, params = 4, B3
    goal, here = _views(params, runs, 5, np.tile([-2.0, -2.0], (runs, 1)), [2.0, 2.0])
    blind = Views(
        here.bearing_rad, np.zeros_like(here.visible), here.alv, here.count, here.rotation_rad
    )
    blind.visible[:, params.features - 1] = True  # sees one feature the goal view does not
    goal.visible[:, params.features - 1] = False
    state = RunState(np.full((runs, 2), np.nan))
    move = best_controller(goal, blind, state, params, np.random.default_rng(0))
    np.testing.assert_array_equal(move, 0.0)


def _success(params, runs, seed, controller, bearings):
    rng = np.random.default_rng(seed)
    result = simulate_runs(params, runs, rng, controller, needs_bearings=bearings)
    return float(np.mean(result.outcome == Outcome.SUCCESS))


def test_best_homes_through_many_fake_features_in_the_one_wall_world():
    # Before matched home vectors: 0 % (every run ended by max distance).
    params = replace(B3, world=4, fake_features=995)
    assert _success(params, 10, 1, best_controller, True) >= 0.9


def test_best_beats_the_thesis_when_most_features_are_removed():
    # Before: the gain collapsed into max-iterations failures (25 % against the thesis's 50 %).
    params = replace(B3, world=1, removed_features=950)
    best = _success(params, 10, 2, best_controller, True)
    thesis = _success(params, 10, 2, thesis_controller, False)
    assert best >= 0.7
    assert best > thesis


def test_gain_never_falls_below_the_thesis_gain():
    params = replace(B3, world=2, removed_features=980)
    runs = 6
    rng = np.random.default_rng(7)
    features = sample_features(params, runs, rng)
    goal = project(features, np.tile(params.goal_xy_m, (runs, 1)), params, rng, True)
    position = np.tile(params.start_xy_m, (runs, 1)).astype(float)
    state = RunState(np.full((runs, 2), np.nan))
    for _ in range(40):
        here = project(features, position, params, rng, True)
        position += best_controller(goal, here, state, params, rng)
        assert np.all(state.extra["gain"] >= GAIN_MIN)
