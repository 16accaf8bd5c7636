"""Angle conventions of toploc's panoramas: wrapping angles, and pixel columns ↔ bearings.

Frames (DESIGN.md, REP-103): a bearing is a robot-frame azimuth in radians, counter-clockwise
positive, 0 along the robot's heading. A cylindrical panorama is ``W`` columns for 360°; column 0
looks along the heading and columns increase clockwise seen from above. OpenCV pixel coordinates
put pixel centres at integers, so a point at column coordinate ``x`` has bearing ``-2*pi*x/W``.

Every wrapped angle in toploc lies in the half-open interval (-half turn, half turn]: (-pi, pi]
radians, (-180, 180] degrees. The wrap is exact: an angle already in range comes back unchanged,
bit for bit, and any other comes back as ``angle - k * turn`` rounded once (as
:func:`math.remainder` gives it), so wrapping twice changes nothing.

Pure numpy, so the localizer, the homing code and the robot's renderer share one convention.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

TWO_PI = 2.0 * np.pi


def _wrap_half_open(angle: ArrayLike, half_turn: float) -> np.ndarray:
    """``angle`` wrapped to (-half_turn, half_turn], exactly (see the module docstring).

    ``np.fmod`` is exact, and its result ``r`` (|r| < turn) moves into range by one addition of
    ``-+turn`` that is exact too (Sterbenz: ``turn / 2 <= |r| <= 2 * turn`` whenever it happens).
    NaN and infinities give NaN.
    """
    turn = 2.0 * half_turn
    with np.errstate(invalid="ignore"):
        r = np.fmod(np.asarray(angle, dtype=float), turn)
    r = np.where(r > half_turn, r - turn, r)
    return np.where(r <= -half_turn, r + turn, r)


def wrap_angle_rad(angle_rad: ArrayLike) -> np.ndarray:
    """Angles in radians wrapped to the half-open interval (-pi, pi]; ``-pi`` becomes ``pi``."""
    return _wrap_half_open(angle_rad, np.pi)


def wrap_angle_deg(angle_deg: ArrayLike) -> np.ndarray:
    """Angles in degrees wrapped to the half-open interval (-180, 180]; -180 becomes 180."""
    return _wrap_half_open(angle_deg, 180.0)


def check_width_px(width_px: int) -> None:
    """Raise ``ValueError`` unless ``width_px`` (columns for 360°) is a positive integer."""
    if int(width_px) != width_px or width_px < 1:
        raise ValueError(f"panorama width must be a positive integer of pixels, got {width_px!r}")


def bearing_rad_from_column(x_px: ArrayLike, width_px: int) -> np.ndarray:
    """Robot-frame azimuth (rad, CCW positive, in (-pi, pi]) of OpenCV column coordinate ``x_px``.

    ``x_px`` may be fractional and outside [0, W): the panorama is periodic.
    """
    check_width_px(width_px)
    x = np.asarray(x_px, dtype=float)
    return wrap_angle_rad(-TWO_PI * x / width_px)


def column_from_bearing(bearing_rad: ArrayLike, width_px: int) -> np.ndarray:
    """OpenCV column coordinate in [0, W) that looks along robot-frame azimuth ``bearing_rad``."""
    check_width_px(width_px)
    b = np.asarray(bearing_rad, dtype=float)
    x = np.mod(-b * width_px / TWO_PI, float(width_px))
    # np.mod can round a tiny negative value up to exactly W; fold it back onto column 0.
    return np.where(x >= width_px, 0.0, x)


def column_shift_px(delta_bearing_rad: float, width_px: int) -> float:
    """Columns to roll a panorama by so that every bearing changes by ``delta_bearing_rad``.

    ``np.roll(image, k, axis=1)`` moves content ``k`` columns right (clockwise), which changes
    every bearing by ``-2*pi*k/W``; this returns that ``k`` (fractional) for a wanted change.
    """
    check_width_px(width_px)
    return -float(delta_bearing_rad) * width_px / TWO_PI


def mean_direction_rad(*directions_rad: ArrayLike) -> np.ndarray:
    """Element-wise circular mean of the directions (radians): the direction of the sum of their
    unit vectors, NaN ones left out; NaN where all are NaN or the vectors cancel."""
    stacked = np.asarray(np.broadcast_arrays(*directions_rad), dtype=float)
    known = np.isfinite(stacked)
    c = np.where(known, np.cos(stacked), 0.0).sum(axis=0)
    s = np.where(known, np.sin(stacked), 0.0).sum(axis=0)
    return np.where(np.hypot(c, s) > 1e-9, np.arctan2(s, c), np.nan)


def signed_axis_rad(axis_rad: ArrayLike, reference_rad: ArrayLike) -> np.ndarray:
    """``axis_rad`` or its opposite, whichever lies within 90° of ``reference_rad``;
    ``reference_rad`` itself where the axis is NaN (radians, the same frame, wrapped).

    For a direction known up to its sign (the axis of an essential matrix's translation),
    signed by a rougher estimate of the same direction.
    """
    axis = np.asarray(axis_rad, dtype=float)
    reference = np.asarray(reference_rad, dtype=float)
    opposite = np.cos(axis - reference) < 0.0
    signed = wrap_angle_rad(np.where(opposite, axis + np.pi, axis))
    return np.where(np.isnan(axis), reference, signed)
