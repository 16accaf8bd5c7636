"""Panorama angle conventions: wrapping, columns ↔ bearings (moved from the localizer's tests)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from homing.bearings import (
    bearing_rad_from_column,
    column_from_bearing,
    column_shift_px,
    mean_direction_rad,
    signed_axis_rad,
    wrap_angle_deg,
    wrap_angle_rad,
)

widths = st.integers(min_value=1, max_value=8192)


def circular_diff(a: np.ndarray, b: np.ndarray, period: float) -> np.ndarray:
    return np.abs((np.asarray(a) - np.asarray(b) + period / 2) % period - period / 2)


@given(width=widths, frac=st.floats(min_value=0.0, max_value=1.0, exclude_max=True))
def test_column_bearing_round_trip(width: int, frac: float) -> None:
    x = frac * width
    back = column_from_bearing(bearing_rad_from_column(x, width), width)
    assert 0.0 <= back < width
    assert circular_diff(back, x, width) < 1e-9 * width


@given(width=widths, bearing=st.floats(min_value=-np.pi, max_value=np.pi, exclude_min=True))
def test_bearing_column_round_trip(width: int, bearing: float) -> None:
    back = bearing_rad_from_column(column_from_bearing(bearing, width), width)
    assert -np.pi < back <= np.pi
    assert circular_diff(back, bearing, 2 * np.pi) < 1e-9


@given(x=st.floats(min_value=-1e6, max_value=1e6), width=widths)
def test_bearing_is_wrapped(x: float, width: int) -> None:
    b = bearing_rad_from_column(x, width)
    assert -np.pi < b <= np.pi


def test_bearing_convention_clockwise_columns() -> None:
    w = 400
    b = bearing_rad_from_column([0.0, 100.0, 200.0, 300.0], w)
    # Column 0 ahead, a quarter turn of columns is the robot's right (-90°), half is behind (+pi).
    np.testing.assert_allclose(b, [0.0, -np.pi / 2, np.pi, np.pi / 2])
    assert wrap_angle_rad(-np.pi) == pytest.approx(np.pi)


def test_column_shift_matches_roll() -> None:
    w = 360
    k = column_shift_px(np.deg2rad(-10.0), w)  # 10° clockwise = 10 columns right
    assert k == pytest.approx(10.0)
    x = np.array([5.0, 355.0])
    shifted = bearing_rad_from_column(x + k, w) - bearing_rad_from_column(x, w)
    np.testing.assert_allclose(wrap_angle_rad(shifted), np.deg2rad(-10.0))


@given(angle=st.floats(min_value=-1e6, max_value=1e6))
def test_wrap_is_math_remainder_with_the_upper_end_kept(angle: float) -> None:
    expected = math.remainder(angle, 2 * math.pi)
    expected = math.pi if expected == -math.pi else expected
    assert float(wrap_angle_rad(angle)) == expected
    assert float(wrap_angle_rad(wrap_angle_rad(angle))) == expected


@given(angle=st.floats(min_value=-1e6, max_value=1e6))
def test_wrap_deg_is_math_remainder_with_the_upper_end_kept(angle: float) -> None:
    expected = math.remainder(angle, 360.0)
    expected = 180.0 if expected == -180.0 else expected
    assert float(wrap_angle_deg(angle)) == expected


def test_wrap_ranges_are_half_open_above() -> None:
    wrapped = wrap_angle_deg([-180.0, 180.0, 540.0, -0.5])
    np.testing.assert_array_equal(wrapped, [180.0, 180.0, 180.0, -0.5])
    assert wrap_angle_rad(np.pi) == np.pi
    assert wrap_angle_rad(3 * np.pi) == pytest.approx(np.pi)
    assert np.isnan(wrap_angle_rad(np.nan))


angles = st.floats(min_value=-10.0, max_value=10.0)


@given(axis=angles, reference=angles)
def test_signed_axis_is_the_axis_either_way_within_90_deg_of_the_reference(axis, reference):
    signed = float(signed_axis_rad(axis, reference))
    assert -np.pi < signed <= np.pi
    either_way = [circular_diff(signed, a, 2 * np.pi) for a in (axis, axis + np.pi)]
    assert min(either_way) < 1e-9
    assert circular_diff(signed, reference, 2 * np.pi) <= np.pi / 2 + 1e-9


def test_signed_axis_without_an_axis_is_the_reference() -> None:
    np.testing.assert_allclose(signed_axis_rad([np.nan, 0.2], [1.0, 0.5]), [1.0, 0.2])
    np.testing.assert_allclose(signed_axis_rad(0.2, 0.2 + np.pi - 0.3), 0.2 - np.pi)


@given(direction=angles)
def test_mean_direction_of_one_direction_or_twice_the_same_is_itself(direction: float) -> None:
    assert circular_diff(mean_direction_rad(direction), direction, 2 * np.pi) < 1e-9
    assert circular_diff(mean_direction_rad(direction, direction), direction, 2 * np.pi) < 1e-9


def test_mean_direction_bisects_across_the_seam_and_leaves_out_nan() -> None:
    assert mean_direction_rad(np.pi - 0.1, -np.pi + 0.3) == pytest.approx(-np.pi + 0.1)
    assert mean_direction_rad(np.nan, 0.4) == pytest.approx(0.4)
    np.testing.assert_allclose(mean_direction_rad([0.0, 1.0], [0.5, np.nan]), [0.25, 1.0])


def test_mean_direction_of_opposites_or_nothing_is_nan() -> None:
    assert np.isnan(mean_direction_rad(0.3, 0.3 + np.pi))
    assert np.isnan(mean_direction_rad(np.nan, np.nan))
