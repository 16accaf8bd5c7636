"""ALV and home vectors: eq. 2.4-2.6 and 5.5, their properties and their errors."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from homing.alv import (
    HomingError,
    alv_from_bearings,
    angular_error_deg,
    average_landmark_vector,
    cylinder_vectors_3d,
    direction_rad,
    home_vector,
    matched_home_vector,
    rotate_vectors_2d,
    unit_vectors_2d,
)

coordinates = st.floats(-10, 10, allow_nan=False, width=64)
points = arrays(np.float64, (2,), elements=coordinates)
landmark_sets = arrays(np.float64, st.tuples(st.integers(3, 40), st.just(2)), elements=coordinates)


def bearings_from(position: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    offset = landmarks - position
    return np.arctan2(offset[:, 1], offset[:, 0])


def test_landmarks_all_around_cancel_out():
    bearings = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    np.testing.assert_allclose(alv_from_bearings(bearings), [0.0, 0.0], atol=1e-12)


def test_cylinder_vectors_keep_the_horizontal_unit_vector():
    vectors = cylinder_vectors_3d([0.0, np.pi / 2], [0.5, -0.25])
    np.testing.assert_allclose(vectors, [[1, 0, 0.5], [0, 1, -0.25]], atol=1e-12)
    np.testing.assert_allclose(vectors[:, :2], unit_vectors_2d([0.0, np.pi / 2]))


@settings(max_examples=200, deadline=None)
@given(landmark_sets, points, points)
def test_home_vector_points_within_90_degrees_of_home(landmarks, here, home):
    """Franz et al.: the ALV is minus the gradient of a convex function, so never > 90 deg off."""
    distances = np.hypot(*(landmarks - here).T), np.hypot(*(landmarks - home).T)
    if min(d.min() for d in distances) < 1e-3 or np.hypot(*(home - here)) < 1e-6:
        return  # a landmark on top of a position has no bearing
    vector = home_vector(
        alv_from_bearings(bearings_from(here, landmarks)),
        alv_from_bearings(bearings_from(home, landmarks)),
    )
    assert np.dot(vector, home - here) >= -1e-9


@settings(max_examples=100, deadline=None)
@given(landmark_sets, points, points)
def test_home_vector_is_exactly_antisymmetric(landmarks, a, b):
    if min(np.hypot(*(landmarks - p).T).min() for p in (a, b)) < 1e-3:
        return
    alv_a = alv_from_bearings(bearings_from(a, landmarks))
    alv_b = alv_from_bearings(bearings_from(b, landmarks))
    assert np.array_equal(home_vector(alv_a, alv_b), -home_vector(alv_b, alv_a))


@settings(max_examples=100, deadline=None)
@given(landmark_sets, points, points, st.floats(-np.pi, np.pi), st.floats(-np.pi, np.pi))
def test_headings_are_compensated(landmarks, here, home, heading_here, heading_home):
    if min(np.hypot(*(landmarks - p).T).min() for p in (here, home)) < 1e-3:
        return
    aligned = home_vector(
        alv_from_bearings(bearings_from(here, landmarks)),
        alv_from_bearings(bearings_from(home, landmarks)),
    )
    turned = home_vector(
        alv_from_bearings(bearings_from(here, landmarks) - heading_here),
        alv_from_bearings(bearings_from(home, landmarks) - heading_home),
        heading_here,
        heading_home,
    )
    c, s = np.cos(heading_here), np.sin(heading_here)
    np.testing.assert_allclose(np.array([[c, -s], [s, c]]) @ turned, aligned, atol=1e-9)


def test_home_vector_in_the_thesis_figure_points_to_home():
    landmarks = np.array([[0.0, 5.0], [5.0, 0.0], [-5.0, 0.0], [0.0, -5.0], [4.0, 4.0]])
    here, home = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    vector = home_vector(
        alv_from_bearings(bearings_from(here, landmarks)),
        alv_from_bearings(bearings_from(home, landmarks)),
    )
    assert angular_error_deg(np.degrees(direction_rad(vector)), 45.0) < 30.0


def test_no_landmarks_is_an_error():
    with pytest.raises(HomingError, match="no landmarks"):
        alv_from_bearings([])


def test_nan_bearing_is_an_error_naming_the_count():
    with pytest.raises(HomingError, match="1 NaN or infinite"):
        alv_from_bearings([0.0, np.nan, 1.0])


def test_infinite_alv_is_an_error():
    with pytest.raises(HomingError, match="finite"):
        home_vector(np.array([np.inf, 0.0]), np.array([0.0, 0.0]))


def test_zero_length_home_vector_has_no_direction():
    vector = home_vector(np.array([0.3, 0.1]), np.array([0.3, 0.1]))
    with pytest.raises(HomingError, match="zero-length"):
        direction_rad(vector)


def test_weights_must_sum_to_something():
    with pytest.raises(HomingError, match="positive"):
        average_landmark_vector(np.ones((3, 2)), weights=np.zeros(3))


def test_weighted_alv_leans_to_heavy_landmarks():
    alv = average_landmark_vector(unit_vectors_2d([0.0, np.pi]), weights=np.array([3.0, 1.0]))
    np.testing.assert_allclose(alv, [0.5, 0.0], atol=1e-12)


@pytest.mark.parametrize(
    ("home_deg", "correct_deg", "error_deg"),
    [(10, 350, 20), (0, 180, 180), (90, 45, 45), (-170, 170, 20), (720, 0, 0)],
)
def test_angular_error_of_eq_5_5(home_deg, correct_deg, error_deg):
    assert angular_error_deg(home_deg, correct_deg) == pytest.approx(error_deg)


def _loop_matched_home(here, goal, rotation, matched):
    """The obvious version: mean over matched features of u(b_here) - R(rotation) u(b_goal)."""
    total, count = np.zeros(2), 0
    for b_here, b_goal, seen in zip(here, goal, matched, strict=True):
        if seen:
            turned = b_goal + rotation
            total += [np.cos(b_here) - np.cos(turned), np.sin(b_here) - np.sin(turned)]
            count += 1
    return total / count if count else np.full(2, np.nan)


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(0, 30),
    seed=st.integers(0, 2**32 - 1),
    rotation=st.floats(-np.pi, np.pi),
)
def test_matched_home_vector_is_the_mean_of_matched_differences(n, seed, rotation):
    rng = np.random.default_rng(seed)
    here, goal = rng.uniform(-np.pi, np.pi, (2, n))
    matched = rng.random(n) < 0.6
    expected = _loop_matched_home(here, goal, rotation, matched)
    found = matched_home_vector(here, goal, rotation, matched)
    np.testing.assert_allclose(found, expected, atol=1e-12)
    in_goal = matched_home_vector(here, goal, rotation, matched, frame="goal")
    np.testing.assert_allclose(in_goal, rotate_vectors_2d(expected, -rotation), atol=1e-12)


def test_matched_home_vector_of_all_features_is_the_home_vector():
    rng = np.random.default_rng(3)
    here, goal = rng.uniform(-np.pi, np.pi, (2, 12))
    expected = home_vector(alv_from_bearings(here), alv_from_bearings(goal), 0.0, 0.7)
    np.testing.assert_allclose(matched_home_vector(here, goal, 0.7), expected, atol=1e-15)


def test_matched_home_vector_batches_rows_and_rejects_mismatched_shapes():
    rng = np.random.default_rng(4)
    here, goal = rng.uniform(-np.pi, np.pi, (2, 3, 8))
    matched = rng.random((3, 8)) < 0.5
    matched[2] = False
    rotation = np.array([0.1, -2.0, 0.5])
    batch = matched_home_vector(here, goal, rotation, matched)
    for row in range(2):
        single = matched_home_vector(here[row], goal[row], rotation[row], matched[row])
        np.testing.assert_allclose(batch[row], single)
    assert np.all(np.isnan(batch[2]))
    with pytest.raises(HomingError, match="differ"):
        matched_home_vector(here[0], goal[0, :5], 0.0)
