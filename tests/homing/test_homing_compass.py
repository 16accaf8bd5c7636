"""Visual compasses on bearings: the thesis's histogram (eq. 5.4) and toploc's smoothed one."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from homing.alv import HomingError
from homing.compass import bearing_histograms, bearing_shift_rad, matched_shift_rad
from homing.thesis.simulation import SimulationParams, project, sample_features


def wrapped_error_deg(a_rad: float, b_rad: float) -> float:
    return float(np.degrees(np.abs(np.angle(np.exp(1j * (a_rad - b_rad))))))


def test_histogram_counts_each_bearing_once():
    counts = bearing_histograms(np.array([[0.0, 0.1, np.pi, -0.1]]), 4)
    np.testing.assert_array_equal(counts, [[2, 0, 1, 1]])


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(-np.pi, np.pi))
def test_pure_rotation_is_recovered(seed, rotation_rad):
    bearings = np.random.default_rng(seed).uniform(-np.pi, np.pi, 300)
    rotated = bearings + rotation_rad
    assert wrapped_error_deg(bearing_shift_rad(bearings, rotated, "histogram"), rotation_rad) < 3.7
    assert wrapped_error_deg(bearing_shift_rad(bearings, rotated, "smoothed"), rotation_rad) < 1.0


def test_empty_view_is_an_error():
    with pytest.raises(HomingError, match="empty"):
        bearing_shift_rad([], [0.1, 0.2])


def test_matched_compass_sees_through_the_symmetric_room():
    """From (-1,-1) and (1,1) a square room looks half-turned; matched bearings are not fooled."""
    params = SimulationParams(world=1)
    rng = np.random.default_rng(3)
    features = sample_features(params, 1, rng)
    a = project(features, np.array([[-1.0, -1.0]]), params, rng, with_bearings=True)
    b = project(features, np.array([[1.0, 1.0]]), params, rng, with_bearings=True)
    shift = matched_shift_rad(a.bearing_rad, b.bearing_rad + 0.5, a.visible & b.visible)[0]
    assert wrapped_error_deg(shift, 0.5) < 15.0


def compass_errors_deg(distance_m: float, trials: int, seed: int) -> dict[str, float]:
    """Mean compass error between views ``distance_m`` apart in the thesis's world 1."""
    params = SimulationParams(world=1)
    rng = np.random.default_rng(seed)
    errors: dict[str, list[float]] = {"histogram": [], "smoothed": []}
    for _ in range(trials):
        features = sample_features(params, 1, rng)
        a = rng.uniform(-1.5, 1.5, 2)
        angle = rng.uniform(0, 2 * np.pi)
        b = a + distance_m * np.array([np.cos(angle), np.sin(angle)])
        view_a = project(features, a[None], params, rng, with_bearings=True)
        view_b = project(features, b[None], params, rng, with_bearings=True)
        rotation = rng.uniform(-np.pi, np.pi)
        bearings_a = view_a.bearing_rad[0][view_a.visible[0]]
        bearings_b = view_b.bearing_rad[0][view_b.visible[0]] + rotation
        for method, found in errors.items():
            found.append(
                wrapped_error_deg(bearing_shift_rad(bearings_a, bearings_b, method), rotation)
            )
    return {method: float(np.mean(found)) for method, found in errors.items()}


def test_smoothed_compass_beats_the_histogram_near_the_snapshot():
    """Measured: at 0.25 m about 1.1 deg against 2.4 deg (100 trials); we ask for 30 % better."""
    errors = compass_errors_deg(0.25, trials=60, seed=11)
    assert errors["smoothed"] < 0.7 * errors["histogram"], errors


def test_smoothed_compass_is_sub_bin_on_the_spot():
    errors = compass_errors_deg(0.0, trials=30, seed=12)
    assert errors["smoothed"] < 0.2 < errors["histogram"], errors
