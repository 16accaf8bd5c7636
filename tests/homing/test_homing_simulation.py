"""The thesis's simulation (appendix A): world, projection, failure criteria, both controllers."""

from dataclasses import replace

import numpy as np
import pytest

from homing.thesis.controller import best_controller
from homing.thesis.experiments import ROW_KEYS, Setting, settings, summarise
from homing.thesis.reference import thesis_rows
from homing.thesis.simulation import (
    Outcome,
    SimulationParams,
    project,
    sample_features,
    simulate_runs,
)


def run(params: SimulationParams, runs: int = 10, seed: int = 0, best: bool = False):
    rng = np.random.default_rng(seed)
    if best:
        return simulate_runs(params, runs, rng, best_controller, needs_bearings=True)
    return simulate_runs(params, runs, rng)


@pytest.mark.parametrize(("world", "walls"), [(1, 4), (2, 2), (3, 2), (4, 1)])
def test_features_are_shared_evenly_over_the_present_walls(world, walls):
    params = SimulationParams(world=world)
    features = sample_features(params, 2, np.random.default_rng(0))
    assert features.shape == (2, 1000, 3)
    on_x_wall = np.abs(np.abs(features[..., 1]) - 2.5) <= params.roughness_m
    on_y_wall = np.abs(np.abs(features[..., 0]) - 2.5) <= params.roughness_m
    assert np.all(on_x_wall | on_y_wall)
    assert np.all((features[..., 2] >= 0) & (features[..., 2] <= 2.0))
    planes = [features[0, :, axis] * sign for axis in (0, 1) for sign in (-1, 1)]
    per_plane = [int(np.sum(np.abs(p - 2.5) <= params.roughness_m)) for p in planes]
    assert sorted(per_plane, reverse=True)[:walls] == [1000 // walls] * walls


def test_projection_sees_only_what_the_camera_can():
    params = SimulationParams(vertical_half_fov_deg=20.0)
    features = np.array([[[2.0, 0.0, 1.0], [0.05, 0.0, 1.0], [0.5, 0.0, 1.9], [0.0, 3.0, 1.1]]])
    views = project(features, np.zeros((1, 2)), params, np.random.default_rng(0), True)
    # ahead: seen; 5 cm away: too close; 0.9 m up at 0.5 m: above the image; left: seen
    np.testing.assert_array_equal(views.visible[0], [True, False, False, True])
    np.testing.assert_allclose(views.bearing_rad[0, [0, 3]], [0.0, np.pi / 2])
    np.testing.assert_allclose(views.alv[0], [0.5, 0.5])


def test_thesis_method_reaches_the_goal_in_the_default_world():
    """Table B.1 world 1 defaults: all 20 succeed, median 12 iterations in the paper."""
    result = run(SimulationParams(world=1), runs=20)
    assert np.all(result.outcome == Outcome.SUCCESS)
    assert 8 <= np.median(result.iterations) <= 16


def test_a_run_that_never_sees_anything_fails_by_empty_projections():
    params = SimulationParams(features=20, removed_features=20)
    result = run(params, runs=3)
    assert np.all(result.outcome == Outcome.MAX_EMPTY_PROJECTIONS)


def test_a_run_out_of_iterations_fails_by_iterations():
    result = run(replace(SimulationParams(), max_iterations=3), runs=3)
    assert np.all(result.outcome == Outcome.MAX_ITERATIONS)
    assert np.all(result.iterations == 3)


def test_a_run_out_of_road_fails_by_distance():
    result = run(replace(SimulationParams(), max_distance_factor=0.2), runs=3)
    assert np.all(result.outcome == Outcome.MAX_DISTANCE)


def test_best_controller_survives_any_rotation_where_the_thesis_does_not():
    """Table B.4 at max rotation pi: the paper and our thesis run fail; alignment fixes it."""
    params = SimulationParams(world=1, max_rotation_rad=np.pi)
    thesis, best = run(params, runs=20), run(params, runs=20, best=True)
    assert np.mean(thesis.outcome == Outcome.SUCCESS) <= 0.2
    assert np.mean(best.outcome == Outcome.SUCCESS) >= 0.9


def test_best_controller_crosses_a_long_room_in_fewer_steps():
    """Table B.1, 50 m long room: the thesis's tiny steps need hundreds of iterations."""
    params = SimulationParams(world=1, wall_length_x_m=50.0)
    thesis, best = run(params, runs=10), run(params, runs=10, best=True)
    assert np.mean(best.outcome == Outcome.SUCCESS) >= np.mean(thesis.outcome == Outcome.SUCCESS)
    assert np.median(best.iterations) < 0.5 * np.median(thesis.iterations)


def test_a_summary_row_has_exactly_the_documented_keys():
    setting = next(settings("B1", (1,)))
    row = summarise(setting, "thesis", run(setting.params, runs=3))
    assert tuple(row) == ROW_KEYS
    assert 0.0 <= row["success_rate"] <= 1.0


def test_a_summary_of_no_success_has_null_statistics():
    setting = Setting("B1", 1, "features", 20, SimulationParams(features=20, removed_features=20))
    row = summarise(setting, "thesis", run(setting.params, runs=2))
    assert row["success_rate"] == 0.0
    assert row["iterations_median"] is None and row["excess_distance_mean"] is None


def test_every_setting_has_a_thesis_reference_row():
    reference = thesis_rows()
    assert len(reference) == 340
    keys = {
        (s.experiment, s.world, s.parameter, round(s.value, 6))
        for e in ("B1", "B2", "B3", "B4")
        for s in settings(e)
    }
    assert keys == set(reference)


def test_bad_parameters_are_refused_with_their_name():
    with pytest.raises(ValueError, match="removed_features"):
        SimulationParams(features=10, removed_features=11)
    with pytest.raises(ValueError, match="world"):
        SimulationParams(world=7)
