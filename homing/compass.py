"""Visual compasses: the rotation between two panoramas from the bearings of their features.

Convention: :func:`bearing_shift_rad` returns ``delta`` such that a feature seen at bearing
``theta`` in the reference view is seen at ``theta + delta`` in the current view (radians,
counter-clockwise). If the robot turned by ``phi`` between the two views, ``delta = -phi``.
To align the current view with the reference, subtract ``delta`` from its bearings (or rotate
its ALV by ``-delta``).

Two methods, both working on circular histograms of bearings:

* ``"histogram"`` — Goldhoorn 2008, section 5.4.1, eq. 5.4: ``n`` equal bins, every circular
  shift tried, the shift with the least sum of squared differences wins; resolution one bin.
* ``"smoothed"`` — toploc's compass: each histogram is normalised to unit mass (so views with
  different feature counts compare), smoothed with a wrapped Gaussian kernel, and the shift is
  the peak of their circular cross-correlation, refined below one bin by a parabola through the
  peak and its neighbours.

Minimising eq. 5.4 is maximising the circular cross-correlation (the squared norms do not depend
on the shift), so both use one FFT correlation; the histograms of a batch of views are rows of
one array.

:func:`compass_rotation_rad` and :func:`matched_rotation_rad` give the same rotation for a
pair of views taken in the order (here, home), the second from descriptor matches.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from homing.alv import HomingError
from homing.bearings import TWO_PI, wrap_angle_rad

CompassMethod = Literal["histogram", "smoothed"]


def bearing_histograms(
    bearings_rad: np.ndarray, n_bins: int, visible: np.ndarray | None = None
) -> np.ndarray:
    """Counts of bearings per bin, one row per view: (r, n) bearings -> (r, n_bins) counts.

    Bin ``i`` covers ``[2*pi*i/n_bins, 2*pi*(i+1)/n_bins)`` after wrapping to ``[0, 2*pi)``.
    ``visible`` (same shape, bool) masks out features that were not seen.
    """
    bearings = np.atleast_2d(np.asarray(bearings_rad, dtype=float))
    if n_bins < 2:
        raise HomingError(f"a compass needs at least 2 bins, got {n_bins}")
    if not np.all(np.isfinite(bearings)):
        raise HomingError("bearings hold NaN or infinite values")
    index = np.floor(np.mod(bearings, TWO_PI) * (n_bins / TWO_PI)).astype(np.int64)
    np.minimum(index, n_bins - 1, out=index)  # a bearing of 2*pi - tiny can round up to n_bins
    index += np.arange(len(bearings))[:, None] * n_bins
    weights = None if visible is None else np.atleast_2d(visible).astype(float).ravel()
    counts = np.bincount(index.ravel(), weights=weights, minlength=len(bearings) * n_bins)
    return counts.reshape(len(bearings), n_bins)


def histogram_spectra(
    histograms: np.ndarray, method: CompassMethod = "smoothed", sigma_deg: float = 4.0
) -> np.ndarray:
    """Fourier spectra (rfft along the last axis) of histograms, prepared for correlation.

    For ``"smoothed"`` each row is normalised to unit mass and multiplied by the spectrum of a
    wrapped Gaussian of ``sigma_deg`` (its Fourier series is ``exp(-k^2 sigma^2 / 2)``). Rows
    with no features get an all-zero spectrum.
    """
    h = np.atleast_2d(np.asarray(histograms, dtype=float))
    spectra = np.fft.rfft(h, axis=-1)
    if method == "histogram":
        return spectra
    if method != "smoothed":
        raise HomingError(f"unknown compass method {method!r}; use 'histogram' or 'smoothed'")
    mass = h.sum(axis=-1, keepdims=True)
    k = np.arange(spectra.shape[-1])
    kernel = np.exp(-0.5 * (k * np.deg2rad(sigma_deg)) ** 2)
    return spectra * kernel / np.where(mass > 0, mass, 1.0)


def shift_from_spectra(
    reference_spectra: np.ndarray, current_spectra: np.ndarray, n_bins: int, subbin: bool
) -> np.ndarray:
    """Bearing shifts (radians, in (-pi, pi]) that best map reference rows onto current rows."""
    correlation = np.fft.irfft(np.conj(reference_spectra) * current_spectra, n=n_bins, axis=-1)
    rows = np.arange(len(correlation))
    best = np.argmax(correlation, axis=-1)
    shift = best.astype(float)
    if subbin:
        left = correlation[rows, (best - 1) % n_bins]
        centre = correlation[rows, best]
        right = correlation[rows, (best + 1) % n_bins]
        curvature = left - 2.0 * centre + right
        with np.errstate(divide="ignore", invalid="ignore"):
            offset = np.where(curvature < 0, 0.5 * (left - right) / curvature, 0.0)
        shift += np.clip(offset, -0.5, 0.5)
    angle = shift * (TWO_PI / n_bins)
    return wrap_angle_rad(angle)


def bearing_shift_rad(
    reference_bearings_rad: np.ndarray | list[float],
    current_bearings_rad: np.ndarray | list[float],
    method: CompassMethod = "smoothed",
    n_bins: int | None = None,
    sigma_deg: float = 4.0,
) -> float:
    """The rotation ``delta`` (radians) from the reference view to the current view.

    ``n_bins`` defaults to 100 for ``"histogram"`` (the thesis's choice) and 360 for
    ``"smoothed"``. Raises :class:`HomingError` when either view has no bearings.
    """
    reference = np.asarray(reference_bearings_rad, dtype=float)
    current = np.asarray(current_bearings_rad, dtype=float)
    if reference.size == 0 or current.size == 0:
        raise HomingError("a compass needs bearings in both views; one of them is empty")
    bins = n_bins if n_bins is not None else (100 if method == "histogram" else 360)
    spectra = histogram_spectra(
        bearing_histograms(np.stack([reference.ravel()]), bins), method, sigma_deg
    )
    current_spectra = histogram_spectra(
        bearing_histograms(np.stack([current.ravel()]), bins), method, sigma_deg
    )
    shift = shift_from_spectra(spectra, current_spectra, bins, subbin=method == "smoothed")
    return float(shift[0])


def matched_shift_rad(
    reference_bearings_rad: np.ndarray, current_bearings_rad: np.ndarray, matched: np.ndarray
) -> np.ndarray:
    """Rotations (r,) from reference to current views whose features correspond column by column.

    Row ``i`` of both bearing arrays (r, n) holds the same features; ``matched`` (r, n) says
    which are seen in both. The estimate is the circular mean of the bearing differences:
    parallax spreads them, but unlike a bearing histogram it cannot confuse a view with its
    mirror image. Rows with no match give NaN.
    """
    difference = np.asarray(current_bearings_rad) - np.asarray(reference_bearings_rad)
    weight = np.asarray(matched, dtype=float)
    resultant_x = (weight * np.cos(difference)).sum(axis=-1)
    resultant_y = (weight * np.sin(difference)).sum(axis=-1)
    shift = np.arctan2(resultant_y, resultant_x)
    return np.where(weight.sum(axis=-1) > 0, shift, np.nan)


def compass_rotation_rad(bearings_here_rad: np.ndarray, bearings_home_rad: np.ndarray) -> float:
    """Rotation home -> here from the smoothed bearing-histogram compass (headings unknown)."""
    return bearing_shift_rad(bearings_home_rad, bearings_here_rad, method="smoothed")


def matched_rotation_rad(
    bearings_here_rad: np.ndarray, bearings_home_rad: np.ndarray, matches: np.ndarray
) -> float:
    """Rotation home -> here from matched features: the circular mean of their bearing changes
    (:func:`matched_shift_rad` for index-pair matches).

    ``matches`` (k, 2) holds ``[here_row, home_row]``. Parallax spreads the changes, but moving
    in any direction shifts features on opposite sides in opposite senses, so the mean is near
    the rotation. NaN when there are no matches.
    """
    m = np.asarray(matches, dtype=np.int64).reshape(-1, 2)
    here, home = bearings_here_rad[m[:, 0]], bearings_home_rad[m[:, 1]]
    return float(matched_shift_rad(home, here, np.ones(len(m), dtype=bool)))
