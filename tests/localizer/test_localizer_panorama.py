"""Panorama geometry: columns ↔ bearings, rows ↔ elevations, band and half masks."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from localizer.panorama import (
    Cylinder,
    bearing_rad_from_column,
    column_from_bearing,
    column_shift_px,
    elevation_rad_from_row,
    horizon_band_mask,
    row_from_elevation,
    rows_mask,
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


@given(
    height=st.integers(min_value=1, max_value=2000),
    focal=st.one_of(st.none(), st.floats(min_value=1.0, max_value=5000.0)),
    frac=st.floats(min_value=0.0, max_value=1.0),
)
def test_row_elevation_round_trip(height: int, focal: float | None, frac: float) -> None:
    cyl = Cylinder(width_px=1024, height_px=height, focal_px=focal)
    y = frac * (height - 1)
    assert row_from_elevation(elevation_rad_from_row(y, cyl), cyl) == pytest.approx(y, abs=1e-6)


def test_cylinder_defaults_and_elevation_sign() -> None:
    cyl = Cylinder(width_px=628, height_px=101)
    assert cyl.f_px == pytest.approx(628 / (2 * np.pi))
    assert cyl.horizon_px == 50.0
    e = elevation_rad_from_row([0.0, 50.0, 100.0], cyl)
    assert e[0] > 0 and e[1] == 0 and e[2] < 0
    # One row at the horizon subtends one column's angle (square pixels on the cylinder).
    assert elevation_rad_from_row(49.0, cyl) == pytest.approx(2 * np.pi / 628, rel=1e-4)


@pytest.mark.parametrize("band_deg", [0.0, 5.0, 10.0, 20.0, 45.0])
def test_horizon_band_mask_rows(band_deg: float) -> None:
    cyl = Cylinder(width_px=512, height_px=96, focal_px=60.0, horizon_row_px=40.0)
    rows = np.arange(96)
    mask = horizon_band_mask(rows, cyl, band_deg)
    half_px = 60.0 * np.tan(np.deg2rad(band_deg))
    np.testing.assert_array_equal(mask, np.abs(rows - 40.0) <= half_px + 1e-9)
    kept = np.flatnonzero(mask)
    assert np.all(np.diff(kept) == 1)  # one contiguous band around the horizon
    assert 40 in kept


def test_horizon_band_none_keeps_all_and_rejects_bad() -> None:
    cyl = Cylinder(width_px=64, height_px=10)
    assert horizon_band_mask(np.arange(10), cyl, None).all()
    with pytest.raises(ValueError, match="band_deg"):
        horizon_band_mask(np.arange(10), cyl, 90.0)


@given(height=st.integers(min_value=1, max_value=500))
def test_lower_upper_partition(height: int) -> None:
    cyl = Cylinder(width_px=64, height_px=height)
    y = np.arange(height, dtype=float)
    lower, upper = rows_mask(y, cyl, "lower"), rows_mask(y, cyl, "upper")
    assert not np.any(lower & upper)
    assert np.all(lower | upper)
    assert rows_mask(y, cyl, "all").all()
    assert np.all(y[lower] >= (height - 1) / 2) and np.all(y[upper] < (height - 1) / 2)


def test_bad_geometry_arguments() -> None:
    with pytest.raises(ValueError, match="width"):
        bearing_rad_from_column(0.0, 0)
    with pytest.raises(ValueError, match="focal_px"):
        Cylinder(width_px=10, height_px=10, focal_px=-1.0)
    with pytest.raises(ValueError, match="rows must be one of"):
        rows_mask([1.0], Cylinder(10, 10), "middle")  # type: ignore[arg-type]
