"""Home directions from the bearings of two views: the thesis's ALV, the matched ALV, and the
vote of matched features' wedges.

Frames: bearings are robot-frame azimuths (radians, CCW, 0 along the heading). ``rotation_rad``
is the compass convention of :mod:`homing.compass`: a feature seen at ``theta`` at home is seen
at ``theta + rotation_rad`` here (``rotation_rad = heading_home - heading_here``). Home
directions are returned in the current robot frame, in radians; NaN where a view gives none.
Descriptor matches come in as index pairs ``[here_row, home_row]``.

Pure numpy. The homing runtime (:mod:`localizer.visual_homing`) steers by them, and ``toploc
eval homing`` (:mod:`toploc.evaluation.homing`) measures them against the truth with the
statistics of :mod:`homing.thesis.evaluation`.
"""

from __future__ import annotations

import numpy as np

from homing.alv import matched_home_vector, rotate_vectors_2d
from homing.bearings import wrap_angle_rad


def _direction_or_nan(vectors: np.ndarray, min_length: float = 1e-9) -> np.ndarray:
    """Directions (rad) of vectors (..., 2); NaN where the vector is (nearly) zero."""
    length = np.hypot(vectors[..., 0], vectors[..., 1])
    return np.where(length > min_length, np.arctan2(vectors[..., 1], vectors[..., 0]), np.nan)


def alv_home_directions_rad(
    alv_here: np.ndarray, alv_home: np.ndarray, rotation_rad: np.ndarray
) -> np.ndarray:
    """Thesis home directions (rad, current robot frame) for a batch of pairs, eq. 2.6.

    ``alv_here`` and ``alv_home`` (k, 2) are ALVs in their own robot frames; the home ALV is
    rotated by ``rotation_rad`` (k,) into the current frame. NaN where the home vector is zero.
    """
    here = np.asarray(alv_here, dtype=float)
    home = np.asarray(alv_home, dtype=float)
    rotated = rotate_vectors_2d(home, np.asarray(rotation_rad, dtype=float))
    return _direction_or_nan(here - rotated)


def matched_alv_direction_rad(
    bearings_here_rad: np.ndarray,
    bearings_home_rad: np.ndarray,
    matches: np.ndarray,
    rotation_rad: float,
) -> float:
    """Home direction (rad, current frame) of :func:`homing.alv.matched_home_vector`.

    With correct pairs the ALV difference is the mean of per-landmark difference vectors
    (Lambrinos et al. 2000), so unmatched clutter seen from only one place cannot bias it.
    NaN without matches, with a NaN rotation or with a zero home vector.
    """
    m = np.asarray(matches, dtype=np.int64).reshape(-1, 2)
    here, home = bearings_here_rad[m[:, 0]], bearings_home_rad[m[:, 1]]
    return float(_direction_or_nan(matched_home_vector(here, home, rotation_rad)))


def wedge_vote_direction_rad(
    bearings_here_rad: np.ndarray,
    bearings_home_rad: np.ndarray,
    matches: np.ndarray,
    rotation_rad: float,
) -> float:
    """Home direction (rad, current frame) that the most matched features agree with.

    A landmark seen along ``u`` here and along ``v`` at home (rotated into the current frame)
    satisfies ``a u - b v = home - here`` with ``a, b > 0``: the home direction lies in the wedge
    from ``u`` to ``-v`` (the arc shorter than pi). Each match votes for the directions in its
    wedge; the direction in the most wedges wins. The wedges' ends cut the circle into pieces
    each inside the same wedges, so the count is exact (no bins: with exact correspondences the
    arc common to all wedges can be narrower than a degree): the centre of the piece in the most
    wedges, or the length-weighted circular mean of the centres of tied pieces. Mismatches vote
    for wrong wedges but cannot outvote a consensus, unlike in an average. NaN without matches
    with finite bearings, or when every wedge is empty. Matches with a NaN bearing are left out.
    """
    m = np.asarray(matches, dtype=np.int64).reshape(-1, 2)
    if len(m) == 0 or not np.isfinite(rotation_rad):
        return float("nan")
    start = bearings_here_rad[m[:, 0]]
    end = bearings_home_rad[m[:, 1]] + rotation_rad + np.pi
    span = wrap_angle_rad(end - start)  # signed arc length in (-pi, pi]
    known = np.isfinite(span)
    if not known.any():
        return float("nan")
    start, span = start[known], span[known]
    low = np.mod(np.where(span >= 0, start, start + span), 2 * np.pi)  # each wedge, CCW
    length = np.abs(span)
    cuts = np.unique(np.mod(np.concatenate([low, low + length]), 2 * np.pi))
    widths = np.diff(np.append(cuts, cuts[0] + 2 * np.pi))
    centres = cuts + widths / 2
    inside = np.mod(centres[None, :] - low[:, None], 2 * np.pi) <= length[:, None]
    votes = inside.sum(axis=0)
    if votes.max() == 0:  # every wedge empty (each landmark on the line through both places)
        return float("nan")
    best = votes == votes.max()
    weights = widths[best]
    return float(
        np.arctan2((weights * np.sin(centres[best])).sum(), (weights * np.cos(centres[best])).sum())
    )
