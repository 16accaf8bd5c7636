"""Geometric verification of matched keypoints: the essential matrix between two panoramas.

Ramisa et al. (2006): the evidence that a query panorama was taken near a stored place is the
number of matched keypoints consistent with one two-view geometry. Both panoramas are 360°, so
the geometry is estimated from unit bearing rays (:meth:`mapdb.records.Fingerprint.rays`), not
from pinhole image points: ``pycolmap.estimate_relative_pose(rays_place, rays_query,
RANSACOptions)`` runs LO-RANSAC with the 5-point solver on rays directly and returns
``cam2_from_cam1``.

Frames and conventions (REP-103 robot frames, x forward, y left, z up, CCW positive):

- ``rotation`` is ``R_query_from_place``: it maps a direction in the place's robot frame into the
  query's robot frame (pycolmap's ``cam2_from_cam1`` with the place as camera 1).
- ``yaw_rad = heading_query - heading_place`` (wrapped to (-pi, pi]): the query's robot frame is
  the place's frame turned by ``yaw_rad`` counter-clockwise, so a landmark seen at bearing ``b``
  from the place appears at about ``b - yaw_rad`` in the query. (``homing.compass`` measures
  ``current ≈ ref + delta``; with the place as reference, ``delta = -yaw_rad``.) This is the
  visual compass for homing.
- ``translation_dir`` is the unit translation ``t`` of ``cam2_from_cam1`` (query frame). Since
  ``x_query = R x_place + t``, the place's centre (``x_place = 0``) lies at ``t`` in the query
  frame: ``translation_dir`` itself is the direction from the query to the place, i.e. the home
  direction when the place is the goal (:func:`home_direction_rad`; pinned by
  ``tests/localizer/test_localizer_verification.py`` on synthetic rays and on renders). It is
  meaningless when the panoramas were taken (almost) at the same spot.

Inliers. pycolmap's own inlier mask also requires every triangulated point to lie in front of both
cameras; with a small baseline (a query taken near the stored place, the case we most want to
score high) the depth of nearly parallel rays has a random sign, so about half the true matches
fail that test. We therefore rescore all pairs under the estimated model: a pair is an inlier when
its tangent Sampson error (first-order angular distance to the epipolar great circles, radians) is
below ``max_error_rad`` and it is not an antipodal twin (which the epipolar constraint cannot tell
apart on a sphere): either the place ray, rotated into the query frame, is less than 90° from the
query ray (distant points, small parallax), or the two rays triangulate in front of both cameras
(points near the camera, seen with more than 90° of parallax, where that depth is well defined).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pycolmap

from homing.bearings import wrap_angle_rad
from localizer.planar import estimate_planar_pose, triangulated_depths

MIN_CORRESPONDENCES = 5  # the 5-point solver's minimal sample
POSE_MOTIONS: tuple[str, ...] = ("general", "planar", "planar-refined")  # VerificationParams.motion


@dataclass(frozen=True)
class VerificationParams:
    """RANSAC settings for :func:`verify`.

    ``max_error_rad``: inlier threshold on the tangent Sampson error (radians; one column of a
    1024-px panorama is 0.0061 rad). ``min_correspondences``: fewer pairs give 0 inliers without
    running RANSAC (at least 5). ``seed``: RANSAC's random seed (deterministic results).
    ``min_trials``/``max_trials``/``confidence``: pycolmap's RANSAC stopping rule.
    ``motion``: ``"general"`` (pycolmap's 5-point essential matrix: any relative pose),
    ``"planar"`` (:mod:`localizer.planar`: a yaw and a horizontal translation, for a camera
    that moves on the floor without tilting; ``planar_trials`` 2-pair samples) or
    ``"planar-refined"`` (the planar pose refined to any relative pose on its inliers,
    :func:`refined_planar_pose`: a camera that tilts a degree or two).
    """

    max_error_rad: float = 0.01
    motion: str = "general"
    planar_trials: int = 300
    min_correspondences: int = 8
    seed: int = 0
    min_trials: int = 100
    max_trials: int = 2000
    confidence: float = 0.999

    def __post_init__(self) -> None:
        if not (np.isfinite(self.max_error_rad) and self.max_error_rad > 0):
            raise ValueError(f"max_error_rad must be positive, got {self.max_error_rad!r}")
        if self.min_correspondences < MIN_CORRESPONDENCES:
            raise ValueError(
                f"min_correspondences must be >= {MIN_CORRESPONDENCES}, "
                f"got {self.min_correspondences!r}"
            )
        if not 0 < self.min_trials <= self.max_trials:
            raise ValueError(
                f"need 0 < min_trials <= max_trials, got {self.min_trials}, {self.max_trials}"
            )
        if not 0 < self.confidence < 1:
            raise ValueError(f"confidence must be in (0, 1), got {self.confidence!r}")
        if self.motion not in POSE_MOTIONS:
            raise ValueError(f"motion must be one of {POSE_MOTIONS}, got {self.motion!r}")
        if self.planar_trials < 1:
            raise ValueError(f"planar_trials must be >= 1, got {self.planar_trials}")
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0 (pycolmap treats -1 as random), got {self.seed}")

    def ransac_options(self) -> pycolmap.RANSACOptions:
        """The pycolmap options (single-threaded, seeded)."""
        return pycolmap.RANSACOptions(
            max_error=float(self.max_error_rad),
            min_num_trials=int(self.min_trials),
            max_num_trials=int(self.max_trials),
            confidence=float(self.confidence),
            random_seed=int(self.seed),
            num_threads=1,
        )


@dataclass(frozen=True)
class Verification:
    """The outcome of :func:`verify` (see the module docstring for frames).

    ``inliers`` is the evidence; ``inlier_pairs`` (k, 2) int64 ``[query_row, place_row]`` are the
    consistent pairs. ``yaw_rad`` is nan, ``rotation`` (R_query_from_place) and
    ``translation_dir`` None when no geometry was found.
    """

    inliers: int
    inlier_pairs: np.ndarray
    yaw_rad: float
    rotation: np.ndarray | None
    translation_dir: np.ndarray | None

    @classmethod
    def none(cls) -> Verification:
        """No geometry: 0 inliers."""
        return cls(0, np.zeros((0, 2), dtype=np.int64), float("nan"), None, None)

    def swapped(self) -> Verification:
        """The same geometry with query and place exchanged: pairs ``[place_row, query_row]``,
        ``-yaw_rad``, ``R_place_from_query = R^T`` and the direction from the place to the
        query in the place's frame, ``-R^T t``."""
        if self.rotation is None or self.translation_dir is None:
            return Verification(self.inliers, self.inlier_pairs[:, ::-1], self.yaw_rad, None, None)
        R_place_from_query = self.rotation.T
        return Verification(
            inliers=self.inliers,
            inlier_pairs=np.ascontiguousarray(self.inlier_pairs[:, ::-1]),
            yaw_rad=float(wrap_angle_rad(-self.yaw_rad)),
            rotation=R_place_from_query,
            translation_dir=-(R_place_from_query @ self.translation_dir),
        )


def _check_rays(name: str, rays: np.ndarray) -> np.ndarray:
    rays = np.asarray(rays, dtype=np.float64)
    if rays.ndim != 2 or rays.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), got {rays.shape}")
    norms = np.linalg.norm(rays, axis=1)
    if not np.all(np.isfinite(norms)) or np.any(norms < 1e-12):
        raise ValueError(f"{name} has non-finite or zero-length rays")
    return rays / norms[:, None]


def _check_pairs(pairs: np.ndarray, n_query: int, n_place: int) -> np.ndarray:
    pairs = np.asarray(pairs)
    if pairs.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    if pairs.ndim != 2 or pairs.shape[1] != 2 or not np.issubdtype(pairs.dtype, np.integer):
        raise ValueError(f"pairs must be (k, 2) integers, got {pairs.shape} {pairs.dtype}")
    pairs = pairs.astype(np.int64)
    if pairs.min() < 0 or pairs[:, 0].max() >= n_query or pairs[:, 1].max() >= n_place:
        raise ValueError(
            f"pairs index outside {n_query} query rays / {n_place} place rays "
            f"(max {pairs[:, 0].max()}, {pairs[:, 1].max()})"
        )
    return pairs


def yaw_from_rotation(R_query_from_place: np.ndarray) -> float:
    """``heading_query - heading_place`` (rad, (-pi, pi]) from ``R_query_from_place``.

    ``R_query_from_place = Rz(yaw)^T``, so ``yaw = atan2(R[0, 1], R[0, 0])``.
    """
    R = np.asarray(R_query_from_place, dtype=np.float64)
    return float(wrap_angle_rad(np.arctan2(R[0, 1], R[0, 0])))


def tangent_sampson_error_rad(
    E: np.ndarray, rays_place: np.ndarray, rays_query: np.ndarray
) -> np.ndarray:
    """(n,) first-order angular distance (rad) of ray pairs from ``rays_query^T E rays_place = 0``.

    The residual ``x2^T E x1`` divided by the norm of its gradient restricted to the tangent
    planes of the two unit rays (a Sampson error on the spheres).
    """
    Ex1 = rays_place @ E.T  # rows: E x1
    Etx2 = rays_query @ E  # rows: E^T x2
    residual = np.einsum("ij,ij->i", rays_query, Ex1)
    g2 = Ex1 - np.einsum("ij,ij->i", Ex1, rays_query)[:, None] * rays_query
    g1 = Etx2 - np.einsum("ij,ij->i", Etx2, rays_place)[:, None] * rays_place
    denom = np.sqrt(np.einsum("ij,ij->i", g1, g1) + np.einsum("ij,ij->i", g2, g2))
    with np.errstate(divide="ignore", invalid="ignore"):
        err = np.abs(residual) / denom
    return np.where(denom > 1e-15, err, np.where(np.abs(residual) < 1e-15, 0.0, np.inf))


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def inlier_mask(
    R_query_from_place: np.ndarray,
    translation_dir: np.ndarray,
    rays_place: np.ndarray,
    rays_query: np.ndarray,
    max_error_rad: float,
) -> np.ndarray:
    """Boolean (n,): the pairs consistent with the pose (see the module docstring)."""
    E = _skew(translation_dir) @ R_query_from_place
    err = tangent_sampson_error_rad(E, rays_place, rays_query)
    rotated = rays_place @ R_query_from_place.T
    same_side = np.einsum("ij,ij->i", rotated, rays_query) > 0.0
    depth_place, depth_query = triangulated_depths(rotated, rays_query, translation_dir)
    in_front = (depth_place > 0.0) & (depth_query > 0.0)
    return (err <= max_error_rad) & (same_side | in_front)


def _relative_pose(
    x_place: np.ndarray, x_query: np.ndarray, params: VerificationParams
) -> tuple[np.ndarray, np.ndarray] | None:
    """``(R_query_from_place, t)`` by the configured solver, or None."""
    if params.motion in ("planar", "planar-refined"):
        planar = estimate_planar_pose(
            x_place, x_query, params.max_error_rad, params.seed, params.planar_trials
        )
        if planar is None:
            return None
        if params.motion == "planar":
            return planar.rotation, planar.translation
        return refined_planar_pose(
            planar.rotation, planar.translation, x_place, x_query, params.max_error_rad
        )
    result = pycolmap.estimate_relative_pose(x_place, x_query, params.ransac_options())
    if result is None:
        return None
    pose = result["cam2_from_cam1"]
    rotation = np.asarray(pose.rotation.matrix(), dtype=np.float64)
    return rotation, np.asarray(pose.translation, dtype=np.float64)


def refined_planar_pose(
    rotation: np.ndarray,
    translation_dir: np.ndarray,
    x_place: np.ndarray,
    x_query: np.ndarray,
    max_error_rad: float,
) -> tuple[np.ndarray, np.ndarray]:
    """A planar pose (``R_query_from_place``, unit ``t``; :mod:`localizer.planar`) refined to
    any relative pose by pycolmap's least squares on the tangent Sampson error of the ray
    pairs (n, 3) that are its inliers within ``max_error_rad``; the planar pose itself if fewer
    than :data:`MIN_CORRESPONDENCES` are, or the refinement fails.

    The planar RANSAC picks which geometry the matches fit: on a scene whose inliers mostly lie
    on the floor, the 5-point solver finds a wrong axis as readily as the right one, and only
    the right one is a yaw and a horizontal translation. The refinement then takes in a tilt of
    the camera of a degree or two, under which the planar model's own axis errs (rolling every
    other panorama of rendered bare houses by 1-2°: docs/homing.md)."""
    mask = inlier_mask(rotation, translation_dir, x_place, x_query, max_error_rad)
    if int(mask.sum()) < MIN_CORRESPONDENCES:
        return rotation, translation_dir
    start = pycolmap.Rigid3d(pycolmap.Rotation3d(rotation), translation_dir)
    result = pycolmap.refine_relative_pose(start, x_place, x_query, mask[:, None])
    if result is None:
        return rotation, translation_dir
    pose = result["cam2_from_cam1"]
    return np.asarray(pose.rotation.matrix(), dtype=np.float64), np.asarray(
        pose.translation, dtype=np.float64
    )


def verify(
    query_rays: np.ndarray,
    place_rays: np.ndarray,
    pairs: np.ndarray,
    params: VerificationParams | None = None,
) -> Verification:
    """Estimate the relative pose of query and place from matched rays; count the inliers.

    ``query_rays`` (n, 3) and ``place_rays`` (m, 3) are unit rays in each panorama's robot frame;
    ``pairs`` (k, 2) are ``[query_row, place_row]`` (as from
    :func:`localizer.matching.match_descriptors`). Fewer than ``params.min_correspondences``
    pairs, or a degenerate set on which RANSAC finds no model, give :meth:`Verification.none`.
    Deterministic for a given ``params.seed``.
    """
    params = params or VerificationParams()
    query_rays = _check_rays("query_rays", query_rays)
    place_rays = _check_rays("place_rays", place_rays)
    pairs = _check_pairs(pairs, len(query_rays), len(place_rays))
    if len(pairs) < params.min_correspondences:
        return Verification.none()
    x_query = query_rays[pairs[:, 0]]
    x_place = place_rays[pairs[:, 1]]
    pose = _relative_pose(x_place, x_query, params)
    if pose is None:
        return Verification.none()
    R, t = pose
    t_norm = float(np.linalg.norm(t))
    if not (np.all(np.isfinite(R)) and np.isfinite(t_norm) and t_norm > 0):
        return Verification.none()
    t = t / t_norm
    mask = inlier_mask(R, t, x_place, x_query, params.max_error_rad)
    return Verification(
        inliers=int(mask.sum()),
        inlier_pairs=pairs[mask],
        yaw_rad=yaw_from_rotation(R),
        rotation=R,
        translation_dir=t,
    )


FLOOR_ELEVATION_DEG = -25.0
"""Homing leaves out matches below this elevation in either panorama (:func:`above_floor`): with
the camera 1.4 m up, the floor within 3 m. Floors repeat (planks, tiles) and barely move between
nearby places, so their matches, often aliased, can outvote the walls in the cheirality test
that sets the sign of the translation (docs/homing.md)."""


def above_floor(
    rays_query: np.ndarray,
    rays_place: np.ndarray,
    matches: np.ndarray,
    min_elevation_deg: float = FLOOR_ELEVATION_DEG,
) -> np.ndarray:
    """The rows of ``matches`` (``[query_row, place_row]``) whose rays both lie above
    ``min_elevation_deg`` (degrees, positive up)."""
    if len(matches) == 0:
        return matches
    z_min = math.sin(math.radians(min_elevation_deg))
    keep = (rays_query[matches[:, 0], 2] > z_min) & (rays_place[matches[:, 1], 2] > z_min)
    return matches[keep]


def cheirality_sign(
    verification: Verification,
    query_rays: np.ndarray,
    place_rays: np.ndarray,
    min_elevation_deg: float = FLOOR_ELEVATION_DEG,
) -> int:
    """+1 when more of the inliers above ``min_elevation_deg`` (degrees, in both panoramas)
    triangulate in front of both cameras than behind both with ``translation_dir`` as it is,
    -1 when fewer (the opposite translation fits them better); over all inliers if that ties,
    and +1 if that ties too. 0 without geometry. Rays as for :func:`verify`.

    The floor is left out of this count only: a floor texture that repeats about once per place
    spacing gives matches that fit the epipolar geometry with the wrong sign of parallax and
    outvote the walls (the rendered house), while its matches still pin the axis down.
    """
    R, t = verification.rotation, verification.translation_dir
    if R is None or t is None or len(verification.inlier_pairs) == 0:
        return 0
    x_query = query_rays[verification.inlier_pairs[:, 0]]
    x_place = place_rays[verification.inlier_pairs[:, 1]]
    depth_place, depth_query = triangulated_depths(x_place @ R.T, x_query, t)
    margin = ((depth_place > 0) & (depth_query > 0)).astype(int) - (
        (depth_place < 0) & (depth_query < 0)
    ).astype(int)
    z_min = math.sin(math.radians(min_elevation_deg))
    above = (x_query[:, 2] > z_min) & (x_place[:, 2] > z_min)
    for votes in (margin[above], margin):
        if votes.sum() != 0:
            return 1 if votes.sum() > 0 else -1
    return 1


ELEVATION_MIN_DEG = 3.0
"""Inliers nearer the horizon than this (degrees, in either panorama) give no distance ratio
from their elevations (:func:`distance_vote`): their tangents are within the noise of zero."""
DISTANCE_MIN_INLIERS = 5
"""Fewer inliers giving a distance ratio give no distance vote (:func:`distance_vote`)."""


def distance_vote(
    verification: Verification,
    query_rays: np.ndarray,
    place_rays: np.ndarray,
    query_sizes: np.ndarray | None = None,
    place_sizes: np.ndarray | None = None,
    min_elevation_deg: float = FLOOR_ELEVATION_DEG,
) -> tuple[int, float]:
    """The side of ``translation_dir``'s axis the place lies on, by how far the inliers are
    from each view: +1 the translation as it is, -1 its opposite, 0 without a vote; and the
    t-statistic of that vote (its sign is the vote's opposite; 0.0 without a vote).

    Two things give the ratio of a point's two distances, ``log(d_place / d_query)``. Its
    elevations: at height h above or below the camera and horizontal distance d it is seen at
    tan e = h / d, so ``log(tan e_query / tan e_place)`` (inliers at least
    :data:`ELEVATION_MIN_DEG` off the horizon, on one side of it in both). Its keypoint's sizes
    (``query_sizes``, ``place_sizes``, one per row of the rays, in one unit for both, e.g.
    :meth:`mapdb.records.Fingerprint.keypoint_sizes_rad`; None: not known): a feature seen
    nearer is larger, ``log(size_query / size_place)``. The points on the side of the axis
    the place lies on are nearer the place; each ratio of an inlier above ``min_elevation_deg``
    (degrees) in both panoramas is weighted by its ray's component along the axis (query frame),
    and their mean against its standard error is the t-statistic. Where the cheirality of
    :func:`cheirality_sign` and the ALVs are weakest, at points near the axis whose bearing
    barely changes, the distance changes most. The floor is left out: its repeating texture
    matches a plank farther on (the rendered house). Fewer than
    :data:`DISTANCE_MIN_INLIERS` inliers giving a ratio: no vote. Rays as for :func:`verify`.
    """
    t = verification.translation_dir
    if t is None or len(verification.inlier_pairs) == 0 or np.hypot(t[0], t[1]) < 1e-6:
        return 0, 0.0
    rows_query, rows_place = verification.inlier_pairs[:, 0], verification.inlier_pairs[:, 1]
    z_query, z_place = query_rays[rows_query, 2], place_rays[rows_place, 2]
    z_floor = math.sin(math.radians(min_elevation_deg))
    above = (z_query > z_floor) & (z_place > z_floor)
    tan_query = z_query / np.sqrt(np.maximum(1.0 - z_query**2, 1e-12))
    tan_place = z_place / np.sqrt(np.maximum(1.0 - z_place**2, 1e-12))
    tan_min = math.tan(math.radians(ELEVATION_MIN_DEG))
    by_elevation = (
        above
        & (np.abs(tan_query) > tan_min)
        & (np.abs(tan_place) > tan_min)
        & (np.sign(tan_query) == np.sign(tan_place))
    )
    ratios = [np.log(np.abs(tan_query[by_elevation]) / np.abs(tan_place[by_elevation]))]
    sides = [by_elevation]
    giving = by_elevation
    if query_sizes is not None and place_sizes is not None:
        size_query = np.asarray(query_sizes, dtype=float)[rows_query]
        size_place = np.asarray(place_sizes, dtype=float)[rows_place]
        by_size = above & (size_query > 0) & (size_place > 0)
        ratios.append(np.log(size_query[by_size] / size_place[by_size]))
        sides.append(by_size)
        giving = giving | by_size
    if int(giving.sum()) < DISTANCE_MIN_INLIERS:
        return 0, 0.0
    axis = np.asarray(t[:2], dtype=float) / float(np.hypot(t[0], t[1]))
    along = query_rays[rows_query, :2] @ axis
    terms = np.concatenate([r * along[m] for r, m in zip(ratios, sides, strict=True)])
    spread = float(terms.std(ddof=1))
    if spread == 0.0 or float(terms.mean()) == 0.0:
        return 0, 0.0
    statistic = float(terms.mean()) / (spread / math.sqrt(len(terms)))
    return (1 if statistic < 0 else -1), statistic


def home_direction_rad(verification: Verification, min_inliers: int = 1) -> float:
    """Direction (rad, CCW from the query's heading, (-pi, pi]) from the query to the place on
    the floor: the azimuth of ``translation_dir`` (see the module docstring). NaN when no
    geometry was found, it has fewer than ``min_inliers`` inliers, or the translation is
    (nearly) vertical."""
    t = verification.translation_dir
    if t is None or verification.inliers < min_inliers or np.hypot(t[0], t[1]) < 1e-6:
        return float("nan")
    return float(np.arctan2(t[1], t[0]))
