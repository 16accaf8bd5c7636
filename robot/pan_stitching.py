"""Stitch photos taken at fixed pan steps (a camera on a pan-tilt unit) into a 360° cylinder,
as in the thesis (Goldhoorn 2008, §2.3 and §5.2).

Each photo is projected onto a cylinder of radius ``f`` (the focal length in pixels; eq. 2.3,
``u = f * atan(x / f)``, ``v = f * y / sqrt(x^2 + f^2)``, done by OpenCV's stitching module,
``cv2.PyRotationWarper("cylindrical", f)``), so a pan by ``alpha`` becomes a horizontal shift of
``f * alpha`` pixels (the *default shift*, eq. 5.1). The actual shift of each neighbouring pair
(and of the last photo to the first) is measured by *translation voting*: SIFT features are
matched (nearest descriptor, ratio test < 0.8), each match proposes the translation
``(dx, dy)`` between its two cylinder points, and a match gets a vote from every other match
whose translation lies within 5 px of its own. The translation with most votes wins, and the
shift is the mean of it and its voters. It is accepted when (thesis's three rules)

1. it has at least 10 votes,
2. it lies within 25 px (x) and 10 px (y) of the default shift (the closing pair, last to first:
   50 px and 30 px, for the errors that add up around the circle),
3. its matches passed the ratio test (``closest / second closest < 0.8``);

otherwise the default shift is used. The pixel figures are the thesis's, for ``f = 800``.

Frames: photo ``k`` was taken ``k`` pan steps *clockwise* (to the right) of photo 0, so a
feature at column ``x`` of photo ``k`` is seen at ``x - dx`` in photo ``k + 1`` (``dx > 0``).
The panorama is ``round(2 * pi * f)`` columns wide (thesis: 5028 for ``f = 800``), column 0 at the
centre of photo 0 (the heading), columns clockwise (:mod:`homing.bearings`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

MAX_MATCHES = 3000
"""Matches used for voting at most (the vote is O(n^2) in memory and time)."""


@dataclass(frozen=True)
class VotingRules:
    """The thesis's translation voting and acceptance rules (§5.2), in cylinder pixels."""

    vote_radius_px: float = 5.0
    min_votes: int = 10
    max_dx_error_px: float = 25.0
    max_dy_error_px: float = 10.0
    closing_max_dx_error_px: float = 50.0
    closing_max_dy_error_px: float = 30.0
    ratio: float = 0.8


@dataclass(frozen=True)
class PairShift:
    """The shift of one photo to the next on the cylinder: the voted one if ``accepted``, else
    the default (``reason`` says which rule failed); ``votes`` of ``matches``."""

    dx_px: float
    dy_px: float
    accepted: bool
    votes: int
    matches: int
    voted_dx_px: float | None = None
    voted_dy_px: float | None = None
    reason: str = ""


@dataclass(frozen=True)
class Stitched:
    """A stitched cylinder (uint8, grey or BGR; radius ``focal_px``, the horizon at row
    ``horizon_row_px``), the photos' column positions (optical axis of each photo), and the
    pair shifts (``shifts[k]``: photo k to k+1; the last, photo N-1 to 0)."""

    image: np.ndarray
    focal_px: float
    horizon_row_px: float
    positions_px: tuple[float, ...]
    shifts: tuple[PairShift, ...] = field(default_factory=tuple)


def default_shift_px(focal_px: float, step_rad: float) -> float:
    """Eq. 5.1: ``s_default = 2*pi*f * alpha / (2*pi) = f * alpha`` (pixels on the cylinder)."""
    return focal_px * step_rad


def focal_from_hfov_px(width_px: int, hfov_deg: float) -> float:
    """The focal length (pixels) of a pinhole photo ``width_px`` wide seeing ``hfov_deg``."""
    if not 0.0 < hfov_deg < 180.0:
        raise ValueError(f"horizontal field of view must be in (0, 180) degrees, got {hfov_deg}")
    return (width_px / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)


def cylinder_points(xy_px: np.ndarray, focal_px: float, size_px: tuple[int, int]) -> np.ndarray:
    """Eq. 2.3: (n, 2) cylinder coordinates ``(f*atan(x/f), f*y/sqrt(x^2+f^2))`` of pixel
    coordinates ``xy_px`` (n, 2) of a ``(width, height)`` photo, ``(x, y)`` taken from the
    image centre."""
    w, h = size_px
    xy = np.asarray(xy_px, dtype=np.float64).reshape(-1, 2)
    x = xy[:, 0] - (w - 1) / 2.0
    y = xy[:, 1] - (h - 1) / 2.0
    return np.column_stack(
        [focal_px * np.arctan2(x, focal_px), focal_px * y / np.hypot(x, focal_px)]
    )


def vote_translation(translations: np.ndarray, radius_px: float) -> tuple[np.ndarray, int]:
    """The winning translation of (n, 2) proposals and its votes: proposal i gets a vote from
    every proposal j != i within ``radius_px`` (Euclidean); the winner is averaged with its
    voters. ``(nan, nan), 0`` for no proposals."""
    d = np.asarray(translations, dtype=np.float64).reshape(-1, 2)
    if len(d) == 0:
        return np.array([np.nan, np.nan]), 0
    near = np.linalg.norm(d[:, None, :] - d[None, :, :], axis=2) <= radius_px
    counts = near.sum(axis=1) - 1  # not voting for itself
    winner = int(np.argmax(counts))
    return d[near[winner]].mean(axis=0), int(counts[winner])


def _grey(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image


def sift_features(image: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """SIFT keypoint positions (n, 2) and descriptors of a photo."""
    keypoints, descriptors = cv2.SIFT.create().detectAndCompute(_grey(image), None)
    return np.array([k.pt for k in keypoints], dtype=np.float64).reshape(-1, 2), descriptors


def ratio_matches(
    features_a: tuple[np.ndarray, np.ndarray | None],
    features_b: tuple[np.ndarray, np.ndarray | None],
    ratio: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Matched positions ``(pa, pb)`` (n, 2 each): for each feature of a its nearest descriptor
    of b, kept when ``closest < ratio * second closest`` (rule 3), at most ``MAX_MATCHES``."""
    (pa, da), (pb, db) = features_a, features_b
    if da is None or db is None or len(da) < 1 or len(db) < 2:
        return np.empty((0, 2)), np.empty((0, 2))
    pairs = cv2.BFMatcher(cv2.NORM_L2).knnMatch(da, db, k=2)
    good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < ratio * p[1].distance]
    good = sorted(good, key=lambda m: m.distance)[:MAX_MATCHES]
    ia = np.array([m.queryIdx for m in good], dtype=int)
    ib = np.array([m.trainIdx for m in good], dtype=int)
    return pa[ia].reshape(-1, 2), pb[ib].reshape(-1, 2)


def pairwise_shift(
    image_a: np.ndarray,
    image_b: np.ndarray,
    focal_px: float,
    step_rad: float,
    rules: VotingRules | None = None,
    closing: bool = False,
    features: tuple[tuple[np.ndarray, np.ndarray | None], ...] | None = None,
) -> PairShift:
    """The cylinder shift from photo a to photo b, taken ``step_rad`` clockwise of a: voted on
    SIFT matches and accepted by the thesis's rules, else the default ``f * step_rad``.
    ``closing``: the pair from the last photo back to the first (wider tolerances).
    ``features``: the two photos' :func:`sift_features`, if already computed."""
    rules = rules or VotingRules()
    fa, fb = features or (sift_features(image_a), sift_features(image_b))
    pa, pb = ratio_matches(fa, fb, rules.ratio)
    h_a, w_a = image_a.shape[:2]
    h_b, w_b = image_b.shape[:2]
    proposals = cylinder_points(pa, focal_px, (w_a, h_a)) - cylinder_points(
        pb, focal_px, (w_b, h_b)
    )
    (dx, dy), votes = vote_translation(proposals, rules.vote_radius_px)
    default = default_shift_px(focal_px, step_rad)
    max_dx = rules.closing_max_dx_error_px if closing else rules.max_dx_error_px
    max_dy = rules.closing_max_dy_error_px if closing else rules.max_dy_error_px
    reason = ""
    if votes < rules.min_votes:
        reason = f"{votes} votes < {rules.min_votes}"
    elif abs(dx - default) > max_dx or abs(dy) > max_dy:
        reason = (
            f"voted ({dx:.1f}, {dy:.1f}) px is beyond ±({max_dx:g}, {max_dy:g}) of the "
            f"default ({default:.1f}, 0)"
        )
    voted_dx, voted_dy = (None, None) if votes == 0 else (float(dx), float(dy))
    if reason:
        return PairShift(default, 0.0, False, votes, len(pa), voted_dx, voted_dy, reason)
    return PairShift(float(dx), float(dy), True, votes, len(pa), voted_dx, voted_dy)


def warp_to_cylinder(image: np.ndarray, focal_px: float) -> tuple[np.ndarray, np.ndarray, int, int]:
    """The photo on the cylinder (OpenCV's cylindrical warper, scale ``f``), its feather weight
    (distance to the warped photo's border, float32), and the column and row of its optical
    axis in the warped image."""
    h, w = image.shape[:2]
    k = np.array(
        [[focal_px, 0, (w - 1) / 2.0], [0, focal_px, (h - 1) / 2.0], [0, 0, 1]], np.float32
    )
    r = np.eye(3, dtype=np.float32)
    warper = cv2.PyRotationWarper("cylindrical", float(focal_px))
    corner, warped = warper.warp(image, k, r, cv2.INTER_LINEAR, cv2.BORDER_CONSTANT)
    ones = np.full((h, w), 255, np.uint8)
    _, mask = warper.warp(ones, k, r, cv2.INTER_NEAREST, cv2.BORDER_CONSTANT)
    weight = cv2.distanceTransform((mask > 0).astype(np.uint8), cv2.DIST_L2, 3)
    return warped, weight.astype(np.float32), -int(corner[0]), -int(corner[1])


def stitch_cylinder(
    images: list[np.ndarray],
    focal_px: float,
    step_deg: float,
    rules: VotingRules | None = None,
) -> Stitched:
    """Stitch ``images`` (same size; photo k taken ``k * step_deg`` clockwise of photo 0) into a
    cylinder ``round(2*pi*f)`` wide, photo 0's centre at column 0, feather-blended.

    When the sweep covers the full circle and the closing shift is accepted, the positions are
    scaled so that the shifts add up to the width (the loop closes)."""
    if len(images) < 2:
        raise ValueError(f"stitching needs at least 2 photos, got {len(images)}")
    sizes = {im.shape for im in images}
    if len(sizes) != 1:
        raise ValueError(f"photos to stitch must share one size, got {sorted(sizes)}")
    if not (math.isfinite(focal_px) and focal_px > 0 and math.isfinite(step_deg) and step_deg > 0):
        raise ValueError(f"focal_px and step_deg must be positive, got {focal_px}, {step_deg}")
    width = round(2.0 * math.pi * focal_px)
    step = math.radians(step_deg)
    features = [sift_features(im) for im in images]
    n = len(images)
    shifts = [
        pairwise_shift(
            images[k], images[(k + 1) % n], focal_px, step, rules, closing=k == n - 1,
            features=(features[k], features[(k + 1) % n]),
        )
        for k in range(n)
    ]  # fmt: skip
    x = np.concatenate([[0.0], np.cumsum([s.dx_px for s in shifts[:-1]])])
    y = np.concatenate([[0.0], np.cumsum([s.dy_px for s in shifts[:-1]])])
    if n * step_deg >= 360.0 - 1e-6 and shifts[-1].accepted:  # a full circle, closed
        x *= width / (x[-1] + shifts[-1].dx_px)
    y -= y.mean()
    image, horizon = _composite(images, focal_px, width, x, y)
    positions = tuple(float(v) for v in x)
    return Stitched(image, float(focal_px), horizon, positions, tuple(shifts))


def _composite(
    images: list[np.ndarray], focal_px: float, width: int, x_px: np.ndarray, y_px: np.ndarray
) -> tuple[np.ndarray, float]:
    """Feather-blend the warped photos into a cylinder ``width`` wide (columns wrap around), and
    the row of the horizon. Photo k's optical axis lands at column ``x_px[k]``, and its rows
    are moved down by ``y_px[k]``."""
    warped = [warp_to_cylinder(im, focal_px) for im in images]
    height = warped[0][0].shape[0]
    channels = images[0].shape[2:]
    total = np.zeros((height, width, *channels), np.float32)
    weights = np.zeros((height, width), np.float32)
    for (photo, weight, axis_col, _), x, y in zip(warped, x_px, y_px, strict=True):
        if photo.shape[1] > width:
            raise ValueError(f"a photo {photo.shape[1]} px wide on the cylinder exceeds 360°")
        columns = np.mod(np.arange(photo.shape[1]) + round(x) - axis_col, width)
        src = np.arange(height)
        dst = src + round(y)
        keep = (dst >= 0) & (dst < height)
        w = weight[src[keep]]
        contribution = photo[src[keep]].astype(np.float32)
        index = np.ix_(dst[keep], columns)  # no column repeats within one photo
        total[index] += contribution * (w[..., None] if channels else w)
        weights[index] += w
    denominator = np.maximum(weights, 1e-6)
    out = total / (denominator[..., None] if channels else denominator)
    image = np.clip(np.rint(out), 0, 255).astype(np.uint8)
    return image, float(warped[0][3])


# --- pan sweeps cut from an equirectangular panorama (known truth, for tests and demos) ----------


def _sample_equirect(
    equirect: np.ndarray, azimuth: np.ndarray, elevation: np.ndarray
) -> np.ndarray:
    """``equirect`` (column x at azimuth ``-2*pi*x/W``, row y at elevation
    ``pi*((H-1)/2 - y)/H``) sampled bilinearly at the given directions (radians)."""
    h, w = equirect.shape[:2]
    map_x = np.mod(-azimuth * w / (2.0 * np.pi), w).astype(np.float32)
    map_y = ((h - 1) / 2.0 - elevation * h / np.pi).astype(np.float32)
    return cv2.remap(equirect, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)


def view_from_equirect(
    equirect: np.ndarray, yaw_cw_deg: float, size_px: tuple[int, int], focal_px: float
) -> np.ndarray:
    """A level pinhole photo ``(width, height)`` of focal ``focal_px`` looking ``yaw_cw_deg``
    clockwise of column 0 of an equirectangular panorama (what a PTU's camera would see)."""
    w, h = size_px
    u, v = np.meshgrid(np.arange(w) - (w - 1) / 2.0, np.arange(h) - (h - 1) / 2.0)
    azimuth = -math.radians(yaw_cw_deg) - np.arctan2(u, focal_px)
    elevation = np.arctan2(-v, np.hypot(u, focal_px))
    return _sample_equirect(equirect, azimuth, elevation)


def cylinder_from_equirect(
    equirect: np.ndarray, focal_px: float, height_px: int, horizon_row_px: float
) -> np.ndarray:
    """The cylinder of radius ``focal_px`` (``round(2*pi*f)`` wide, ``height_px`` rows, the
    horizon at ``horizon_row_px``) that a perfect stitch of photos of ``equirect`` gives."""
    width = round(2.0 * math.pi * focal_px)
    col, row = np.meshgrid(np.arange(width, dtype=float), np.arange(height_px, dtype=float))
    azimuth = -2.0 * np.pi * col / width
    elevation = np.arctan2(horizon_row_px - row, focal_px)
    return _sample_equirect(equirect, azimuth, elevation)
