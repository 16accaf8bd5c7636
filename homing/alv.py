"""Average Landmark Vector homing (Lambrinos et al. 2000; Goldhoorn 2008, section 2.4).

Frames: a robot frame is REP-103 (x forward, y left, z up); bearings are azimuths in radians,
counter-clockwise positive, 0 along the robot's heading. A heading is the robot frame's yaw in
the world (or room) frame, in radians, counter-clockwise from the world x axis.

The ALV is the mean of unit landmark vectors (eq. 2.4); the home vector is the difference of the
ALV here and the ALV at home, both expressed in one frame (eq. 2.6). Without depth the home
vector's length is not a distance: only its direction is meaningful.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from homing.bearings import wrap_angle_deg

HomeFrame = Literal["here", "goal"]


class HomingError(ValueError):
    """Input from which no landmark vector or home vector can be computed."""


def _finite_1d(values: np.ndarray | list[float], name: str) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if array.ndim != 1:
        raise HomingError(f"{name} must be a 1-D array, got shape {array.shape}")
    if not np.all(np.isfinite(array)):
        bad = int(np.count_nonzero(~np.isfinite(array)))
        raise HomingError(f"{name} holds {bad} NaN or infinite value(s) of {array.size}")
    return array


def unit_vectors_2d(bearings_rad: np.ndarray | list[float]) -> np.ndarray:
    """Unit vectors (n, 2) on the horizon toward landmarks at ``bearings_rad`` (robot frame)."""
    bearings = _finite_1d(bearings_rad, "bearings_rad")
    return np.column_stack([np.cos(bearings), np.sin(bearings)])


def cylinder_vectors_3d(
    bearings_rad: np.ndarray | list[float], heights: np.ndarray | list[float]
) -> np.ndarray:
    """Points (n, 3) on the unit cylinder around the camera, as the thesis's simulation uses.

    ``heights`` are the landmarks' heights on a cylinder of radius 1: ``dz / horizontal range``,
    i.e. ``tan(elevation)``. The horizontal part is the unit vector of :func:`unit_vectors_2d`.
    """
    bearings = _finite_1d(bearings_rad, "bearings_rad")
    z = _finite_1d(heights, "heights")
    if z.shape != bearings.shape:
        raise HomingError(f"heights has {z.size} values for {bearings.size} bearings")
    return np.column_stack([np.cos(bearings), np.sin(bearings), z])


def average_landmark_vector(
    landmark_vectors: np.ndarray, weights: np.ndarray | None = None
) -> np.ndarray:
    """The (weighted) mean of landmark vectors (n, d) -> (d,), eq. 2.4.

    Raises :class:`HomingError` for no landmarks, non-finite input, or weights that do not sum to
    a positive number: an ALV of nothing has no direction, and a silent NaN would steer a robot.
    """
    vectors = np.asarray(landmark_vectors, dtype=float)
    if vectors.ndim != 2 or vectors.shape[1] not in (2, 3):
        raise HomingError(f"landmark vectors must have shape (n, 2) or (n, 3), got {vectors.shape}")
    if len(vectors) == 0:
        raise HomingError("no landmarks: the ALV of an empty view is undefined")
    if not np.all(np.isfinite(vectors)):
        raise HomingError("landmark vectors hold NaN or infinite values")
    if weights is None:
        return vectors.mean(axis=0)
    w = _finite_1d(weights, "weights")
    if w.shape != (len(vectors),):
        raise HomingError(f"weights has {w.size} values for {len(vectors)} landmarks")
    total = w.sum()
    if not total > 0:
        raise HomingError(f"weights must sum to a positive number, got {total}")
    return (w[:, None] * vectors).sum(axis=0) / total


def alv_from_bearings(bearings_rad: np.ndarray | list[float]) -> np.ndarray:
    """The 2-D ALV (robot frame, unitless, norm <= 1) of landmarks seen at ``bearings_rad``.

    The mean of ``(cos b, sin b)``, each component summed on its own (numpy's pairwise sum; the
    ALV stored with every map fingerprint is this one, bit for bit). Raises
    :class:`HomingError` for no bearings or non-finite ones.
    """
    bearings = _finite_1d(bearings_rad, "bearings_rad")
    if bearings.size == 0:
        raise HomingError("no landmarks: the ALV of an empty view is undefined")
    return np.array([np.cos(bearings).mean(), np.sin(bearings).mean()])


def rotation_2d(angle_rad: float) -> np.ndarray:
    """The 2x2 matrix rotating vectors counter-clockwise by ``angle_rad``."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s], [s, c]])


def rotate_vectors_2d(vectors: np.ndarray, angle_rad: np.ndarray | float) -> np.ndarray:
    """Vectors (..., 2) rotated counter-clockwise by ``angle_rad`` (broadcast over ``...``)."""
    v = np.asarray(vectors, dtype=float)
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def matched_home_vector(
    bearings_here_rad: np.ndarray,
    bearings_goal_rad: np.ndarray,
    rotation_rad: np.ndarray | float,
    matched: np.ndarray | None = None,
    frame: HomeFrame = "here",
) -> np.ndarray:
    """The home vector (..., 2) from features seen both here and at the goal (eq. 2.6).

    Entry ``j`` of ``bearings_here_rad`` and ``bearings_goal_rad`` (..., k) is one landmark (a
    descriptor match, or a simulated feature's identity); ``matched`` (..., k, bool; default all)
    says which entries were seen in both views. The ALV is taken over the matched landmarks in
    each view, so unmatched clutter cannot bias it (Lambrinos et al. 2000), and
    ``ALV(here) - R(rotation) ALV(goal)`` is returned. ``rotation_rad`` (...) is the compass
    convention of :mod:`homing.compass`, goal -> here (a goal bearing ``b`` is seen at
    ``b + rotation`` here); with matched features it is usually their circular mean bearing
    change, :func:`homing.compass.matched_shift_rad`.

    ``frame``: ``"here"`` expresses the vector in the current robot frame; ``"goal"`` in the
    goal view's frame, i.e. turned by ``-rotation``: ``R(-rotation) ALV(here) - ALV(goal)``.
    Unitless; NaN where nothing is matched or the rotation is NaN. Raises :class:`HomingError`
    for bearing arrays of different shapes.
    """
    here = np.asarray(bearings_here_rad, dtype=float)
    goal = np.asarray(bearings_goal_rad, dtype=float)
    if here.shape != goal.shape:
        raise HomingError(f"bearings here {here.shape} and at the goal {goal.shape} differ")
    mask = np.ones(here.shape, dtype=bool) if matched is None else np.asarray(matched, dtype=bool)
    count = mask.sum(axis=-1)[..., None]
    with np.errstate(invalid="ignore", divide="ignore"):
        alv_here = _masked_unit_sum(here, mask) / count
        alv_goal = _masked_unit_sum(goal, mask) / count
    if frame == "here":
        return alv_here - rotate_vectors_2d(alv_goal, rotation_rad)
    if frame == "goal":
        return rotate_vectors_2d(alv_here, -np.asarray(rotation_rad)) - alv_goal
    raise HomingError(f"unknown frame {frame!r}; use 'here' or 'goal'")


def _masked_unit_sum(bearings_rad: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Sum (..., 2) of the unit vectors toward the bearings (..., k) where ``mask`` holds."""
    x = np.where(mask, np.cos(bearings_rad), 0.0).sum(axis=-1)
    y = np.where(mask, np.sin(bearings_rad), 0.0).sum(axis=-1)
    return np.stack([x, y], axis=-1)


def home_vector(
    alv_here: np.ndarray,
    alv_home: np.ndarray,
    heading_here_rad: float = 0.0,
    heading_home_rad: float = 0.0,
) -> np.ndarray:
    """The home vector (eq. 2.6) in the current robot frame, headings compensated.

    ``alv_here`` is in the current robot frame, ``alv_home`` in the robot frame at home; the
    headings are the two robot frames' yaw in one common frame (radians). Only the horizontal
    components of 3-D ALVs are used. Raises :class:`HomingError` for non-finite input.
    """
    here = np.asarray(alv_here, dtype=float)[:2]
    home = np.asarray(alv_home, dtype=float)[:2]
    if here.shape != (2,) or home.shape != (2,):
        raise HomingError(f"ALVs must have 2 or 3 components, got {alv_here!r} and {alv_home!r}")
    headings = np.array([heading_here_rad, heading_home_rad], dtype=float)
    if not (
        np.all(np.isfinite(here)) and np.all(np.isfinite(home)) and np.all(np.isfinite(headings))
    ):
        raise HomingError("ALVs and headings must be finite")
    home_in_here = rotation_2d(heading_home_rad - heading_here_rad) @ home
    return here - home_in_here


def direction_rad(vector: np.ndarray, min_length: float = 1e-12) -> float:
    """Direction of a 2-D vector in radians (counter-clockwise from x), in (-pi, pi].

    A vector shorter than ``min_length`` has no direction: :class:`HomingError` (the ALV is the
    same here and at home; section 2.4 suggests a small random move then).
    """
    v = np.asarray(vector, dtype=float)[:2]
    if not np.all(np.isfinite(v)):
        raise HomingError(f"vector {vector!r} is not finite")
    if float(np.hypot(v[0], v[1])) < min_length:
        raise HomingError(f"vector {vector!r} is zero-length: it has no direction")
    return float(np.arctan2(v[1], v[0]))


def angular_error_deg(home_deg: np.ndarray | float, correct_deg: np.ndarray | float) -> np.ndarray:
    """Eq. 5.5: the absolute difference of two directions in degrees, in [0, 180]."""
    difference = np.asarray(correct_deg, dtype=float) - np.asarray(home_deg, dtype=float)
    return np.abs(wrap_angle_deg(difference))
