"""Homing on images, evaluated: the error statistics of home directions (Goldhoorn 2008).

Sections 5.6-5.7: for every ordered pair of panoramas of one room, a home vector is computed
from the panorama here to the panorama at home (:mod:`homing.home_directions`), and its
direction is compared with the true direction from the positions (eq. 5.5). The errors give the
mean, median, standard deviation, the score of eq. 5.6 and the "best home" (the home with the
least mean error) of tables C.1-C.3, and the share of errors under 90° and under 10° (section
5.7.1); figure 5.4 bins them by distance.

Frames: home directions are in the current robot frame (radians, CCW, 0 along the heading),
true directions and positions in the room's frame (radians, metres).

Pure numpy: no file I/O, no OpenCV.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from homing.alv import HomingError, angular_error_deg

FAILED_ERROR_DEG = 90.0
"""Error charged to a pair whose home vector is undefined (the expected error of a random move)."""


@dataclass(frozen=True)
class HomingStats:
    """Error statistics of a set of home vectors (tables C.1-C.3, section 5.7.1).

    ``n`` is the number of panoramas, ``n_pairs`` the ordered pairs evaluated, ``n_failed`` those
    with no home vector (charged ``FAILED_ERROR_DEG``). ``score`` is eq. 5.6, ``1 - mean/180``.
    ``best_home`` is the home whose incoming home vectors have the least mean error.
    ``under_90`` / ``under_10`` are the fractions of errors at or below 90° / 10°.
    """

    n: int
    n_pairs: int
    n_failed: int
    mean_deg: float
    median_deg: float
    std_deg: float
    score: float
    best_home: str
    under_90: float
    under_10: float

    def to_json(self, **extra: Any) -> dict[str, Any]:
        """The statistics as a JSON-ready dict, ``extra`` keys (e.g. detector, method) first."""
        return {
            **extra,
            "n": self.n,
            "n_pairs": self.n_pairs,
            "n_failed": self.n_failed,
            "mean_deg": self.mean_deg,
            "median_deg": self.median_deg,
            "std_deg": self.std_deg,
            "score": self.score,
            "best_home": self.best_home,
            "under_90": self.under_90,
            "under_10": self.under_10,
        }


def homing_statistics(
    errors_deg: np.ndarray, current_ids: np.ndarray, home_ids: np.ndarray
) -> HomingStats:
    """Statistics of per-pair angular errors (degrees; NaN = failed pair) with their place ids.

    Eq. 5.6 is ``1 - sum(errors) / (180 n (n - 1))`` over all ordered pairs of one room; over
    several rooms it is ``1 - mean / 180`` over every evaluated pair. The standard deviation is
    the sample one (``ddof=1``, as Matlab's ``std``). Raises :class:`HomingError` for no pairs,
    mismatched lengths, or errors outside [0, 180].
    """
    errors = np.asarray(errors_deg, dtype=float)
    here = np.asarray(current_ids).astype(str)
    home = np.asarray(home_ids).astype(str)
    if errors.ndim != 1 or errors.size == 0:
        raise HomingError(f"need a 1-D array of at least one pair error, got shape {errors.shape}")
    if here.shape != errors.shape or home.shape != errors.shape:
        raise HomingError(f"{errors.size} errors but {here.size} current and {home.size} home ids")
    finite = np.isfinite(errors)
    if np.any((errors[finite] < 0) | (errors[finite] > 180)):
        raise HomingError("angular errors must lie in [0, 180] degrees (eq. 5.5)")
    charged = np.where(finite, errors, FAILED_ERROR_DEG)
    homes, index = np.unique(home, return_inverse=True)
    per_home = np.bincount(index, weights=charged) / np.bincount(index)
    mean = float(charged.mean())
    return HomingStats(
        n=len(np.union1d(here, home)),
        n_pairs=int(errors.size),
        n_failed=int(np.count_nonzero(~finite)),
        mean_deg=mean,
        median_deg=float(np.median(charged)),
        std_deg=float(charged.std(ddof=1)) if errors.size > 1 else 0.0,
        score=1.0 - mean / 180.0,
        best_home=str(homes[int(np.argmin(per_home))]),
        under_90=float(np.mean(charged <= 90.0)),
        under_10=float(np.mean(charged <= 10.0)),
    )


def true_home_direction_rad(position_here_m: np.ndarray, position_home_m: np.ndarray) -> np.ndarray:
    """Direction (rad, CCW from the room's x axis) from here to home; positions (..., 2) metres."""
    d = np.asarray(position_home_m, dtype=float) - np.asarray(position_here_m, dtype=float)
    return np.arctan2(d[..., 1], d[..., 0])


def pair_errors_deg(
    home_direction_rad: np.ndarray, heading_here_rad: np.ndarray, true_direction_rad: np.ndarray
) -> np.ndarray:
    """Eq. 5.5 for home directions in the current robot frame, against true room-frame ones."""
    room_frame = np.asarray(home_direction_rad) + np.asarray(heading_here_rad)
    return angular_error_deg(np.rad2deg(room_frame), np.rad2deg(true_direction_rad))


@dataclass(frozen=True)
class DistanceBin:
    """Alignment errors of pairs whose distance lies in ``[low_m, high_m)``, in degrees."""

    low_m: float
    high_m: float
    n: int
    mean_deg: float
    std_deg: float
    median_deg: float


def errors_by_distance(
    distances_m: np.ndarray, errors_deg: np.ndarray, bin_width_m: float = 0.5
) -> list[DistanceBin]:
    """Errors binned by pair distance (figure 5.4); NaN errors (no estimate) count as 90°.

    Empty bins are left out. Raises :class:`HomingError` for mismatched lengths or a
    non-positive bin width.
    """
    d = np.asarray(distances_m, dtype=float)
    e = np.asarray(errors_deg, dtype=float)
    if d.shape != e.shape or d.ndim != 1:
        raise HomingError(f"distances {d.shape} and errors {e.shape} must be equal 1-D arrays")
    if not bin_width_m > 0:
        raise HomingError(f"bin width must be positive, got {bin_width_m}")
    e = np.where(np.isfinite(e), e, FAILED_ERROR_DEG)
    index = np.floor(d / bin_width_m).astype(np.int64)
    bins = []
    for k in np.unique(index):
        chosen = e[index == k]
        bins.append(
            DistanceBin(
                low_m=float(k * bin_width_m),
                high_m=float((k + 1) * bin_width_m),
                n=int(chosen.size),
                mean_deg=float(chosen.mean()),
                std_deg=float(chosen.std(ddof=1)) if chosen.size > 1 else 0.0,
                median_deg=float(np.median(chosen)),
            )
        )
    return bins
