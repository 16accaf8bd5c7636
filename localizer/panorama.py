"""Vertical geometry of a cylindrical 360° panorama: rows ↔ elevations, horizon band, row masks.

Conventions (DESIGN.md, REP-103): rows grow downwards (OpenCV pixel centres at integers);
elevation is positive above the horizon. Columns ↔ bearings and angle wrapping are
:mod:`homing.bearings` (one convention for the localizer, homing and the renderer).

Everything here is pure numpy: scalars or arrays in, float arrays (or boolean masks) out.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from homing.bearings import check_width_px

RowsSelection = Literal["all", "lower", "upper"]
ROWS_SELECTIONS: tuple[str, ...] = ("all", "lower", "upper")


@dataclass(frozen=True)
class Cylinder:
    """Vertical geometry of a cylindrical panorama of ``width_px`` x ``height_px``.

    ``focal_px`` is the cylinder radius in pixels (distance from the projection centre to the
    image surface). ``None`` assumes square pixels on the cylinder, ``W / (2*pi)``: one column is
    as wide in angle as one row is high at the horizon. Unwrapped mirror images are not true
    cylinders (rows follow the mirror profile); pass a calibrated focal length for them.
    ``horizon_row_px`` is the row coordinate of zero elevation; ``None`` means the image centre
    row ``(H - 1) / 2``.
    """

    width_px: int
    height_px: int
    focal_px: float | None = None
    horizon_row_px: float | None = None

    def __post_init__(self) -> None:
        check_width_px(self.width_px)
        if int(self.height_px) != self.height_px or self.height_px < 1:
            raise ValueError(f"panorama height must be a positive integer, got {self.height_px!r}")
        if self.focal_px is not None and not (np.isfinite(self.focal_px) and self.focal_px > 0):
            raise ValueError(f"focal_px must be a positive finite number, got {self.focal_px!r}")
        if self.horizon_row_px is not None and not np.isfinite(self.horizon_row_px):
            raise ValueError(f"horizon_row_px must be finite, got {self.horizon_row_px!r}")

    @property
    def f_px(self) -> float:
        """The focal length in pixels actually used (the default resolved)."""
        return float(self.width_px / (2.0 * np.pi) if self.focal_px is None else self.focal_px)

    @property
    def horizon_px(self) -> float:
        """The horizon row coordinate actually used (the default resolved)."""
        return float(
            (self.height_px - 1) / 2.0 if self.horizon_row_px is None else self.horizon_row_px
        )


def elevation_rad_from_row(y_px: ArrayLike, cylinder: Cylinder) -> np.ndarray:
    """Elevation (rad, positive up) of row coordinate ``y_px`` (down) on ``cylinder``.

    On a cylinder of radius ``f`` a point ``h - y`` pixels above the horizon row ``h`` is seen at
    ``atan((h - y) / f)``.
    """
    y = np.asarray(y_px, dtype=float)
    return np.arctan2(cylinder.horizon_px - y, cylinder.f_px)


def row_from_elevation(elevation_rad: ArrayLike, cylinder: Cylinder) -> np.ndarray:
    """Row coordinate (down) at which elevation ``elevation_rad`` (in (-pi/2, pi/2)) is imaged."""
    e = np.asarray(elevation_rad, dtype=float)
    return cylinder.horizon_px - cylinder.f_px * np.tan(e)


def horizon_band_mask(y_px: ArrayLike, cylinder: Cylinder, band_deg: float | None) -> np.ndarray:
    """True where row coordinate ``y_px`` is within ±``band_deg`` degrees of the horizon.

    ``band_deg=None`` keeps everything. Pass ``np.arange(H)`` for a per-row mask of the image, or
    keypoint y coordinates to filter keypoints.
    """
    y = np.asarray(y_px, dtype=float)
    if band_deg is None:
        return np.ones(y.shape, dtype=bool)
    if not (np.isfinite(band_deg) and 0.0 <= band_deg < 90.0):
        raise ValueError(f"band_deg must be in [0, 90), got {band_deg!r}")
    elevation_rad = elevation_rad_from_row(y, cylinder)
    # A hair of slack so a row lying exactly on the band edge is kept despite rounding.
    return np.abs(elevation_rad) <= np.deg2rad(band_deg) + 1e-12


def rows_mask(y_px: ArrayLike, cylinder: Cylinder, rows: RowsSelection) -> np.ndarray:
    """True where row coordinate ``y_px`` lies in the selected half of the panorama.

    ``"lower"`` is at or below the horizon row (``y >= h``; closer objects, thesis §5.9),
    ``"upper"`` strictly above it (``y < h``), so the two halves partition the image;
    ``"all"`` keeps everything.
    """
    y = np.asarray(y_px, dtype=float)
    if rows == "all":
        return np.ones(y.shape, dtype=bool)
    if rows == "lower":
        return y >= cylinder.horizon_px
    if rows == "upper":
        return y < cylinder.horizon_px
    raise ValueError(f"rows must be one of {ROWS_SELECTIONS}, got {rows!r}")
