"""Relative pose of two panoramas taken on one floor: a yaw and a horizontal translation.

A robot's camera moves on the floor and does not tilt, so between two of its panoramas the
rotation is a yaw ``Rz(theta)`` and the translation ``t = (tx, ty, 0)``. The essential matrix
``E = [t]x Rz(theta)`` then has the form

    E = [[0, 0, a], [0, 0, b], [c, d, 0]],   a = ty, b = -tx,
    (c, d) = (tx sin(theta) - ty cos(theta), tx cos(theta) + ty sin(theta)),

with two degrees of freedom (``a^2 + b^2 = c^2 + d^2``). Each ray pair ``x2^T E x1 = 0``
(``x1`` in the place's frame, ``x2`` in the query's) is one linear equation in ``(a, b, c, d)``,
so two pairs fix ``E`` up to the quadratic constraint: at most two solutions
(:func:`planar_essentials`). In RANSAC a 2-pair sample is all inliers far more often than the
5-point solver's 5-pair sample (with 80 % outliers: 4 % against 0.03 %), and a 2-parameter model
lets fewer chance matches agree with it: what matters with the 10–30 matches of a bare room.

Written here (numpy, vectorised over samples) because pycolmap and OpenCV solve only the
general 5-point problem. Frames: REP-103 robot frames; the result is ``R_query_from_place`` and
the unit translation of ``query = R place + t`` (pycolmap's ``cam2_from_cam1`` with the place as
camera 1), as :mod:`localizer.verification` reports.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def planar_essential(yaw_rad: float, translation_xy: np.ndarray) -> np.ndarray:
    """``E = [t]x Rz(yaw)`` for ``t = (tx, ty, 0)`` (the model's forward direction)."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    t = np.array([translation_xy[0], translation_xy[1], 0.0])
    return _skew(t) @ rotation


def _rows(x_place: np.ndarray, x_query: np.ndarray) -> np.ndarray:
    """(..., 4) coefficients of ``(a, b, c, d)`` in ``x2^T E x1`` for ray pairs."""
    u1, v1, w1 = x_place[..., 0], x_place[..., 1], x_place[..., 2]
    u2, v2, w2 = x_query[..., 0], x_query[..., 1], x_query[..., 2]
    return np.stack([u2 * w1, v2 * w1, w2 * u1, w2 * v1], axis=-1)


def planar_essentials(x_place: np.ndarray, x_query: np.ndarray) -> np.ndarray:
    """(k, 2 * s, 4) candidate ``(a, b, c, d)`` (unit norm; NaN where a sample has no real
    solution) from ``s`` samples of two ray pairs each: ``x_place``, ``x_query`` (s, 2, 3).

    The two equations leave a 2-D null space ``e = alpha n1 + beta n2``; the constraint
    ``a^2 + b^2 - c^2 - d^2 = 0`` is a quadratic form in ``(alpha, beta)`` with up to two real
    roots.
    """
    equations = _rows(x_place, x_query)  # (s, 2, 4)
    _, _, vt = np.linalg.svd(equations)  # rows 2 and 3 of vt span the null space
    n1, n2 = vt[:, 2, :], vt[:, 3, :]
    sign = np.array([1.0, 1.0, -1.0, -1.0])
    # q(alpha, beta) = A alpha^2 + 2 B alpha beta + C beta^2
    qa = np.sum(sign * n1 * n1, axis=1)
    qb = np.sum(sign * n1 * n2, axis=1)
    qc = np.sum(sign * n2 * n2, axis=1)
    # solve for r = alpha / beta: qa r^2 + 2 qb r + qc = 0 (and beta = 0 if qa == 0)
    disc = qb**2 - qa * qc
    root = np.sqrt(np.where(disc >= 0, disc, np.nan))
    with np.errstate(divide="ignore", invalid="ignore"):
        r1 = np.where(np.abs(qa) > 1e-12, (-qb + root) / qa, -qc / (2 * qb))
        r2 = np.where(np.abs(qa) > 1e-12, (-qb - root) / qa, np.inf)
    candidates = []
    for r in (r1, r2):
        finite = np.isfinite(r)[:, None]
        e = np.where(finite, r[:, None] * n1 + n2, n1)  # r = inf: beta = 0, e = n1
        e = np.where(np.isnan(r)[:, None], np.nan, e)
        candidates.append(e / np.linalg.norm(e, axis=1, keepdims=True))
    return np.stack(candidates, axis=1).reshape(-1, 4)


def pose_from_planar(e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(R_query_from_place, unit t)`` of one planar ``(a, b, c, d)``, t up to sign."""
    a, b, c, d = e
    tx, ty = -b, a
    norm = np.hypot(tx, ty)
    tx, ty = tx / norm, ty / norm
    # [c, d] = [[-ty, tx], [tx, ty]] [cos, sin] (scaled by |t|); the matrix is its own inverse
    cos, sin = -ty * c + tx * d, tx * c + ty * d
    theta = np.arctan2(sin, cos)
    rotation = np.array(
        [[np.cos(theta), -np.sin(theta), 0.0], [np.sin(theta), np.cos(theta), 0.0], [0, 0, 1.0]]
    )
    return rotation, np.array([tx, ty, 0.0])


def tangent_errors(essentials: np.ndarray, x_place: np.ndarray, x_query: np.ndarray) -> np.ndarray:
    """(k, n) tangent Sampson error (rad) of ``n`` ray pairs under ``k`` planar essentials
    (k, 4): ``|x2^T E x1|`` over the norm of its gradient in the rays' tangent planes."""
    a, b, c, d = (essentials[:, i, None] for i in range(4))
    u1, v1, w1 = x_place[None, :, 0], x_place[None, :, 1], x_place[None, :, 2]
    u2, v2, w2 = x_query[None, :, 0], x_query[None, :, 1], x_query[None, :, 2]
    ex1 = np.stack([a * w1, b * w1, c * u1 + d * v1])  # E x1, (3, k, n)
    etx2 = np.stack([c * w2, d * w2, a * u2 + b * v2])  # E^T x2
    residual = u2 * ex1[0] + v2 * ex1[1] + w2 * ex1[2]
    x1 = np.stack([u1, v1, w1])
    x2 = np.stack([u2, v2, w2])
    g2 = ex1 - np.sum(ex1 * x2, axis=0) * x2
    g1 = etx2 - np.sum(etx2 * x1, axis=0) * x1
    denom = np.sqrt(np.sum(g1 * g1, axis=0) + np.sum(g2 * g2, axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(denom > 1e-15, np.abs(residual) / denom, np.inf)


@dataclass(frozen=True)
class PlanarPose:
    """A planar relative pose: ``rotation`` (R_query_from_place, a yaw) and the unit
    ``translation`` of ``query = R place + t`` (z = 0), and the RANSAC inlier mask."""

    rotation: np.ndarray
    translation: np.ndarray
    inliers: np.ndarray


def estimate_planar_pose(
    x_place: np.ndarray,
    x_query: np.ndarray,
    max_error_rad: float,
    seed: int = 0,
    trials: int = 200,
) -> PlanarPose | None:
    """RANSAC over ``trials`` random 2-pair samples of the matched rays (n, 3) each; the model
    with the lowest truncated squared error (MSAC: most pairs within ``max_error_rad``, ties to
    the tighter fit) wins and is refined by least squares on its inliers. ``None`` with fewer
    than 2 pairs or no model. The sign of ``t`` is chosen so that most inliers triangulate in
    front of both cameras."""
    n = len(x_place)
    if n < 2:
        return None
    rng = np.random.default_rng(seed)
    first = rng.integers(0, n, trials)
    second = (first + rng.integers(1, n, trials)) % n  # a different pair
    samples = np.stack([first, second], axis=1)
    essentials = planar_essentials(x_place[samples], x_query[samples])
    essentials = essentials[np.all(np.isfinite(essentials), axis=1)]
    if not len(essentials):
        return None
    errors = tangent_errors(essentials, x_place, x_query)
    cost = np.minimum(errors, max_error_rad) ** 2
    best = int(np.argmin(cost.sum(axis=1)))
    e, error, best_cost = essentials[best], errors[best], float(cost[best].sum())
    # Local optimisation: Cauchy-weighted refits on ever tighter inliers, each kept only if it
    # lowers the truncated cost (an outlier inside the band must not pull the model off).
    for band_rad in (max_error_rad, max_error_rad / 2, max_error_rad / 3):
        mask = error <= band_rad
        if mask.sum() < 3:
            break
        weights = 1.0 / (1.0 + (error[mask] / (max_error_rad / 4)) ** 2)
        refit = _least_squares(x_place[mask], x_query[mask], weights)
        refit_error = tangent_errors(refit[None], x_place, x_query)[0]
        refit_cost = float(np.sum(np.minimum(refit_error, max_error_rad) ** 2))
        if refit_cost < best_cost:
            e, error, best_cost = refit, refit_error, refit_cost
    mask = error <= max_error_rad
    rotation, translation = pose_from_planar(e)
    if _in_front(rotation, translation, x_place[mask], x_query[mask]) < 0:
        translation = -translation
    return PlanarPose(rotation, translation, mask)


def _least_squares(x_place: np.ndarray, x_query: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The planar ``(a, b, c, d)`` (unit norm) that best satisfies the pairs with ``weights``:
    the smallest right singular vector of their weighted equations, with ``(a, b)`` and
    ``(c, d)`` scaled to equal norms (the closest point of the constraint)."""
    equations = np.sqrt(weights)[:, None] * _rows(x_place, x_query)
    # the thin SVD gives the same right singular vectors, bit for bit, without the (m, m) left
    # ones (20 times faster at 300 pairs); with fewer than 4 pairs only the full one has vt[3]
    _, _, vt = np.linalg.svd(equations, full_matrices=len(equations) < 4)
    e = vt[-1]
    ab, cd = np.linalg.norm(e[:2]), np.linalg.norm(e[2:])
    if ab < 1e-12 or cd < 1e-12:
        return e
    e = np.concatenate([e[:2] / ab, e[2:] / cd])
    return e / np.linalg.norm(e)


def _in_front(
    rotation: np.ndarray, translation: np.ndarray, x_place: np.ndarray, x_query: np.ndarray
) -> int:
    """Pairs triangulating in front of both cameras minus those behind, for this sign of t."""
    d_place, d_query = triangulated_depths(x_place @ rotation.T, x_query, translation)
    front = (d_place > 0) & (d_query > 0)  # parallel rays have depth 0: neither
    behind = (d_place < 0) & (d_query < 0)
    return int(front.sum()) - int(behind.sum())


def triangulated_depths(
    rotated_place: np.ndarray, rays_query: np.ndarray, translation_dir: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Depths ``(d_place, d_query)`` (units of the baseline) of the closest approach of the
    rays ``d_place * rotated_place + t`` and ``d_query * rays_query`` (query frame; the place
    rays already rotated into it): the least-squares solution of
    ``d_place * a - d_query * c = -t``. Parallel rays get depth 0 (no triangulation)."""
    k = np.einsum("ij,ij->i", rotated_place, rays_query)
    a_t = rotated_place @ translation_dir
    c_t = rays_query @ translation_dir
    det = 1.0 - k**2
    ok = det > 1e-9
    safe = np.where(ok, det, 1.0)
    d_place = np.where(ok, (k * c_t - a_t) / safe, 0.0)
    d_query = np.where(ok, (c_t - k * a_t) / safe, 0.0)
    return d_place, d_query
