"""Panorama geometry: rows ↔ elevations, band and half masks (columns: test_homing_bearings)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from homing.bearings import bearing_rad_from_column
from localizer.panorama import (
    Cylinder,
    elevation_rad_from_row,
    horizon_band_mask,
    row_from_elevation,
    rows_mask,
)


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
