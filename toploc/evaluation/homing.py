"""Homing and alignment on a panorama dataset (Goldhoorn 2008, sections 5.4 and 5.6-5.7).

The adapter of :mod:`homing.home_directions` and :mod:`homing.thesis.evaluation`: reads a
dataset folder (``manifest.csv`` + images), extracts one fingerprint per image (once per run;
optionally in a *spawn* process pool), and evaluates every ordered pair of places of the same
room (positions are in each room's frame).

Methods (``METHODS``): ``"thesis"`` is the ALV of all feature bearings with the headings of the
manifest (section 5.6). The others work without headings:

* ``"alv-compass"``: the thesis's ALV, the rotation from the smoothed bearing-histogram compass;
* ``"matched-alv"``: the ALV of descriptor-matched features only, the rotation from the circular
  mean of their bearing changes;
* ``"matched-vote"``: the home direction in the most wedges of matched features (see
  :func:`homing.home_directions.wedge_vote_direction_rad`), the rotation as for ``matched-alv``;
* ``"pose"``: the direction of the translation of the relative pose that the essential-matrix
  verification finds on the matched rays (:func:`localizer.verification.verify`, solved for
  planar motion as the closed loop does: :data:`localizer.visual_homing.HOMING_VERIFICATION`;
  :func:`localizer.verification.home_direction_rad`), falling back to ``"matched-alv"`` when
  the verification finds no geometry; every ``pose*`` method takes this pose;
* ``"pose-alv"``: the axis of that translation, signed to agree with ``"matched-alv"`` (within
  90° of it), when the verification has at least ``POSE_MIN_INLIERS`` inliers; else
  ``"matched-alv"``. The essential matrix fixes the axis of motion well, but its sign comes
  from which side of both cameras the matched points triangulate on, and a floor texture that
  repeats about once per place spacing (the rendered house) puts most matches on the wrong
  side: the raw translation then points away from home (see docs/homing.md);
* ``"pose-above-floor"``: ``"pose"`` from the matches above
  :data:`localizer.verification.FLOOR_ELEVATION_DEG` in both panoramas (the floor within 3 m
  left out), falling back to ``"matched-alv"`` (of all matches) without geometry;
* ``"pose-compass"``: the thesis's ALV of all features, the rotation from the verified pose's
  yaw (the thesis method with the verification as its compass), ``"matched-alv"`` without
  geometry;
* ``"pose-vote"``: the axis of the verified translation (any inlier count) with the sign that
  the inliers' change of distance gives where it is significant (their elevations and
  keypoint sizes: :func:`localizer.visual_homing.counted_distance_vote`), else the sign that
  most of three votes give: the pose's cheirality counted on the inliers above the floor
  (:func:`localizer.verification.cheirality_sign`), ``"matched-alv"`` and
  ``"pose-compass"``; ``"matched-alv"`` without geometry
  (:func:`localizer.visual_homing.signed_pose_direction_rad`, the closed loop's ``"pose"``
  variant). Each vote fails on different pairs (see that function).

The matched methods fall back to ``"alv-compass"`` for a pair whose matches give no home
vector (no match, or a single one: aligning it zeroes the vector). MSER on these panoramas finds
few features, so this happens for MSER pairs.

Images are read through their camera model (:func:`localizer.features.extract_with_camera`,
``camera`` as ``--camera``: ``auto`` reads a 2:1 image as equirectangular), so the horizon band
and the lower and upper halves are elevations of that model.

``"best"`` (``BEST_METHOD``) is the one chosen on the photo rooms, the house and the rendered lab,
square and corridor, and confirmed on bare houses and photo rooms rendered after the choice
(docs/homing.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from homing.alv import alv_from_bearings, angular_error_deg
from homing.bearings import signed_axis_rad
from homing.compass import bearing_shift_rad, compass_rotation_rad, matched_rotation_rad
from homing.home_directions import (
    alv_home_directions_rad,
    matched_alv_direction_rad,
    wedge_vote_direction_rad,
)
from homing.thesis.evaluation import (
    DistanceBin,
    HomingStats,
    errors_by_distance,
    homing_statistics,
    pair_errors_deg,
    true_home_direction_rad,
)
from localizer.cameras import parse_camera
from localizer.features import DEFAULT_PARAMS, extract_with_camera
from localizer.matching import match_descriptors
from localizer.panorama_io import read_panorama
from localizer.verification import (
    Verification,
    VerificationParams,
    above_floor,
    cheirality_sign,
    home_direction_rad,
    verify,
)
from localizer.visual_homing import (
    HOMING_VERIFICATION,
    counted_distance_vote,
    signed_pose_direction_rad,
)
from mapdb.dataset import ManifestEntry, read_manifest
from mapdb.records import Fingerprint
from mapdb.workers import results_in_order, spawn_process_pool

METHODS: tuple[str, ...] = (
    "thesis",
    "best",
    "alv-compass",
    "matched-alv",
    "matched-vote",
    "pose",
    "pose-alv",
    "pose-above-floor",
    "pose-compass",
    "pose-vote",
)
BEST_METHOD = "pose-vote"
POSE_MIN_INLIERS = 40
"""``pose-alv`` trusts a verified pose with at least this many inliers (measured on the photo
rooms, house, lab, square and corridor: docs/homing.md)."""
COMPASSES: tuple[str, ...] = ("histogram", "smoothed", "matched")


class EvaluationError(ValueError):
    """A dataset cannot be evaluated; the message names the file or the missing values."""


@dataclass(frozen=True)
class HomingRun:
    """Every evaluated ordered pair (``here``, ``home`` index into ``places``) and the stats."""

    places: tuple[ManifestEntry, ...]
    here: np.ndarray
    home: np.ndarray
    home_direction_rad: np.ndarray  # in the current robot frame; NaN when undefined
    errors_deg: np.ndarray  # eq. 5.5, NaN when undefined
    stats: HomingStats


@dataclass(frozen=True)
class AlignmentRun:
    """Per compass: the alignment error of every same-room pair, and the errors by distance."""

    distances_m: np.ndarray
    errors_deg: dict[str, np.ndarray]
    bins: dict[str, list[DistanceBin]]


def load_places(dataset_dir: Path | str) -> tuple[ManifestEntry, ...]:
    """The manifest rows of ``dataset_dir`` with a position; ``EvaluationError`` if none has one.

    Manifest problems (missing folder or file, bad header or value) raise
    :class:`mapdb.errors.ManifestError` naming the file and line.
    """
    places = tuple(e for e in read_manifest(dataset_dir) if e.x_m is not None and e.y_m is not None)
    if not places:
        manifest = Path(dataset_dir) / "manifest.csv"
        raise EvaluationError(f"{manifest}: no rows with a position (x_m, y_m) to evaluate")
    return places


@dataclass(frozen=True)
class FeatureSettings:
    """How the evaluations extract features: a detector preset of
    :data:`localizer.features.PRESETS` (``"sift"``, ``"mser"``), the ``--camera`` text
    (:func:`localizer.cameras.parse_camera`), the horizon band (± degrees of elevation, None:
    all), the half of the rows (``"all"``, ``"lower"``, ``"upper"``) and the contrast
    equalisation's clip limit (0: the images as given; the product's 1,000-keypoint cap still
    applies)."""

    detector: str = "sift"
    camera: str = "auto"
    band_deg: float | None = None
    rows: str = "all"
    clahe_clip_limit: float = DEFAULT_PARAMS.clahe_clip_limit

    def extract(self, image: np.ndarray) -> Fingerprint:
        """The fingerprint of a grey panorama, read through its camera model."""
        band: dict[str, Any] = {} if self.band_deg is None else {"band_deg": self.band_deg}
        camera = parse_camera(self.camera)
        return extract_with_camera(
            image,
            camera,
            self.detector,
            rows=self.rows,
            clahe_clip_limit=self.clahe_clip_limit,
            **band,
        )


def _extract_one(path: Path, settings: FeatureSettings) -> Fingerprint:
    import cv2

    cv2.setNumThreads(1)  # one process per core already
    return settings.extract(read_panorama(path))


def extract_fingerprints(
    paths: Sequence[Path], settings: FeatureSettings, workers: int = 1, progress: bool = False
) -> list[Fingerprint]:
    """One fingerprint per image, in order; a pool of ``workers`` spawned processes if > 1.

    An unreadable image raises :class:`localizer.panorama_io.PanoramaError` naming the file.
    """
    bar = tqdm(total=len(paths), desc=f"extract {settings.detector}", disable=not progress)
    try:
        if workers <= 1:
            results = []
            for path in paths:
                results.append(settings.extract(read_panorama(path)))
                bar.update()
            return results
        with spawn_process_pool(workers) as pool:
            futures = [pool.submit(_extract_one, path, settings) for path in paths]
            results = []
            for result in results_in_order(pool, futures):
                results.append(result)
                bar.update()
            return results
    finally:
        bar.close()


def same_room_pairs(rooms: Sequence[str]) -> np.ndarray:
    """Ordered pairs ``(k, 2)`` ``[here, home]`` of distinct indices whose rooms are equal."""
    r = np.asarray(rooms)
    same = (r[:, None] == r[None, :]) & ~np.eye(len(r), dtype=bool)
    return np.argwhere(same).astype(np.int64)


class PairCache:
    """Descriptor matches and verified relative poses of unordered pairs of one list of
    fingerprints, each computed once on first use and shared by every method evaluated on them.

    ``matches(a, b)`` are ``[row in a, row in b]``; ``verification(a, b)`` has ``a`` as the
    query and ``b`` as the place (its ``translation_dir`` points from ``a`` to ``b`` in ``a``'s
    robot frame, see :mod:`localizer.verification`). ``params``: the verification's (the
    closed loop's planar pose by default).
    """

    def __init__(
        self,
        fingerprints: Sequence[Fingerprint],
        progress: bool = False,
        params: VerificationParams = HOMING_VERIFICATION,
    ) -> None:
        self.fingerprints = tuple(fingerprints)
        self.progress = progress
        self.params = params
        self._matches: dict[tuple[int, int], np.ndarray] = {}
        self._verifications: dict[tuple[int, int, bool], Verification] = {}
        self._rays: dict[int, np.ndarray] = {}

    def rays(self, i: int) -> np.ndarray:
        """The unit rays of fingerprint ``i``'s keypoints (computed once)."""
        if i not in self._rays:
            self._rays[i] = self.fingerprints[i].rays()
        return self._rays[i]

    def holds(self, fingerprints: Sequence[Fingerprint]) -> bool:
        """Whether this cache is of exactly these fingerprint objects, in this order."""
        return len(fingerprints) == len(self.fingerprints) and all(
            a is b for a, b in zip(fingerprints, self.fingerprints, strict=True)
        )

    def prepare(self, pairs: np.ndarray, verified: bool = False, floor: bool = True) -> None:
        """Compute the matches (and, if ``verified``, the poses: with the floor's matches, or
        without them) of all of ``pairs`` at once."""
        keys = sorted({(min(a, b), max(a, b)) for a, b in pairs.tolist()})
        todo = [k for k in keys if k not in self._matches]
        for i, j in tqdm(todo, desc="match", disable=not self.progress):
            self.matches(i, j)
        if verified:
            todo = [k for k in keys if (*k, floor) not in self._verifications]
            for i, j in tqdm(todo, desc="verify", disable=not self.progress):
                self.verification(i, j, floor)

    def matches(self, a: int, b: int) -> np.ndarray:
        """Matches ``(k, 2)`` ``[row in a, row in b]`` (Lowe's ratio, cross-checked)."""
        i, j = min(a, b), max(a, b)
        if (i, j) not in self._matches:
            fps = self.fingerprints
            self._matches[(i, j)] = match_descriptors(fps[i].descriptors, fps[j].descriptors)
        m = self._matches[(i, j)]
        return m if a <= b else m[:, ::-1]

    def verification(self, a: int, b: int, floor: bool = True) -> Verification:
        """The relative pose of ``a`` (query) and ``b`` (place) from their matched rays; without
        ``floor``, from those above :data:`localizer.verification.FLOOR_ELEVATION_DEG`."""
        i, j = min(a, b), max(a, b)
        if (i, j, floor) not in self._verifications:
            rays_i, rays_j = self.rays(i), self.rays(j)
            matches = self.matches(i, j)
            if not floor:
                matches = above_floor(rays_i, rays_j, matches)
            self._verifications[(i, j, floor)] = verify(rays_i, rays_j, matches, self.params)
        v = self._verifications[(i, j, floor)]
        return v if a <= b else v.swapped()


def positions_m(places: Sequence[ManifestEntry]) -> np.ndarray:
    """``(n, 2)`` positions ``[x_m, y_m]`` of places, each in its room's frame (metres).

    For places of :func:`load_places`, which all have a position.
    """
    return np.array([(p.x_m, p.y_m) for p in places], dtype=float).reshape(-1, 2)


def headings_rad(places: Sequence[ManifestEntry]) -> np.ndarray:
    """``(n,)`` headings of places in their room frames (radians, CCW); NaN where unknown."""
    return np.array(
        [np.nan if p.heading_deg is None else math.radians(p.heading_deg) for p in places],
        dtype=float,
    )


def _true_rotations(places: Sequence[ManifestEntry], pairs: np.ndarray) -> np.ndarray:
    h = headings_rad(places)
    missing = sorted({places[i].image for i in pairs.ravel() if np.isnan(h[i])})
    if missing:
        raise EvaluationError(
            f"the true home direction in the robot frame needs headings; {len(missing)} "
            f"row(s) lack heading_deg, e.g. {missing[0]}"
        )
    return h[pairs[:, 1]] - h[pairs[:, 0]]


def _thesis_directions(
    places: Sequence[ManifestEntry], bearings: Sequence[np.ndarray], pairs: np.ndarray
) -> np.ndarray:
    alvs = np.array([alv_from_bearings(b) if len(b) else [0.0, 0.0] for b in bearings])
    directions = alv_home_directions_rad(
        alvs[pairs[:, 0]], alvs[pairs[:, 1]], _true_rotations(places, pairs)
    )
    empty = np.array([len(bearings[i]) == 0 or len(bearings[j]) == 0 for i, j in pairs])
    return np.where(empty, np.nan, directions)


def _compass_directions(bearings: Sequence[np.ndarray], pairs: np.ndarray) -> np.ndarray:
    alvs = np.array([alv_from_bearings(b) if len(b) else [0.0, 0.0] for b in bearings])
    rotations = np.array(
        [
            compass_rotation_rad(bearings[i], bearings[j])
            if len(bearings[i]) and len(bearings[j])
            else np.nan
            for i, j in pairs
        ]
    )
    return alv_home_directions_rad(alvs[pairs[:, 0]], alvs[pairs[:, 1]], rotations)


def _home_directions(
    method: str, places: Sequence[ManifestEntry], cache: PairCache, pairs: np.ndarray
) -> np.ndarray:
    """Home directions (rad, the current robot frame; NaN where undefined) of ``pairs``."""
    bearings = [f.bearings_rad for f in cache.fingerprints]
    if method == "thesis":
        return _thesis_directions(places, bearings, pairs)
    if method == "alv-compass":
        return _compass_directions(bearings, pairs)
    out = np.full(len(pairs), np.nan)
    if method in ("pose", "pose-above-floor"):
        floor = method == "pose"
        cache.prepare(pairs, verified=True, floor=floor)
        out = np.array(
            [home_direction_rad(cache.verification(i, j, floor)) for i, j in pairs.tolist()]
        )
        fallback = np.isnan(out)  # no geometry: the matched ALV
        if np.any(fallback):
            out[fallback] = _home_directions("matched-alv", places, cache, pairs[fallback])
        return out
    if method == "pose-alv":
        matched = _home_directions("matched-alv", places, cache, pairs)
        cache.prepare(pairs, verified=True)
        axis = np.array(
            [
                home_direction_rad(cache.verification(i, j), POSE_MIN_INLIERS)
                for i, j in pairs.tolist()
            ]
        )
        return signed_axis_rad(axis, matched)
    if method in ("pose-compass", "pose-vote"):
        matched = _home_directions("matched-alv", places, cache, pairs)
        cache.prepare(pairs, verified=True)
        alvs = np.array([alv_from_bearings(b) if len(b) else [np.nan, np.nan] for b in bearings])
        verifications = [cache.verification(i, j) for i, j in pairs.tolist()]
        if method == "pose-vote":
            return np.array(
                [
                    signed_pose_direction_rad(
                        v,
                        m,
                        alvs[i],
                        alvs[j],
                        cheirality_sign(v, cache.rays(i), cache.rays(j)),
                        counted_distance_vote(
                            v,
                            cache.rays(i),
                            cache.rays(j),
                            cache.fingerprints[i].keypoint_sizes_rad(),
                            cache.fingerprints[j].keypoint_sizes_rad(),
                        ),
                    )
                    for v, m, (i, j) in zip(verifications, matched, pairs.tolist(), strict=True)
                ]
            )
        yaws = np.array([v.yaw_rad for v in verifications])
        out = alv_home_directions_rad(alvs[pairs[:, 0]], alvs[pairs[:, 1]], -yaws)
        return np.where(np.isnan(out), matched, out)
    estimate = {"matched-alv": matched_alv_direction_rad, "matched-vote": wedge_vote_direction_rad}
    cache.prepare(pairs)
    for k, (i, j) in enumerate(pairs.tolist()):
        m = cache.matches(i, j)
        rotation = matched_rotation_rad(bearings[i], bearings[j], m)
        out[k] = estimate[method](bearings[i], bearings[j], m, rotation)
    fallback = np.isnan(out)
    if np.any(fallback):  # no match, or one (its rotation zeroes the home vector): thesis ALV
        out[fallback] = _compass_directions(bearings, pairs[fallback])
    return out


def evaluate_homing(
    places: Sequence[ManifestEntry],
    fingerprints: Sequence[Fingerprint],
    method: str = "thesis",
    progress: bool = False,
    cache: PairCache | None = None,
) -> HomingRun:
    """Home vectors for every ordered same-room pair with ``method``, and their statistics.

    ``cache`` (of these ``fingerprints``) shares matches and poses between methods. Raises
    :class:`EvaluationError` for an unknown method, a length mismatch, no room with two places,
    or (``thesis``) a pair without headings.
    """
    if method not in METHODS:
        raise EvaluationError(f"unknown method {method!r}; known: {', '.join(METHODS)}")
    method = BEST_METHOD if method == "best" else method
    if len(places) != len(fingerprints):
        raise EvaluationError(f"{len(places)} places but {len(fingerprints)} fingerprints")
    pairs = same_room_pairs([p.room for p in places])
    if len(pairs) == 0:
        raise EvaluationError("no room has two places with positions: nothing to home to")
    _true_rotations(places, pairs)  # the ground truth needs every heading, whatever the method
    if cache is None or not cache.holds(fingerprints):
        cache = PairCache(fingerprints, progress)
    directions = _home_directions(method, places, cache, pairs)
    positions = positions_m(places)
    truth = true_home_direction_rad(positions[pairs[:, 0]], positions[pairs[:, 1]])
    errors = pair_errors_deg(directions, headings_rad(places)[pairs[:, 0]], truth)
    stats = homing_statistics(
        errors,
        np.array([places[i].image for i in pairs[:, 0]]),
        np.array([places[j].image for j in pairs[:, 1]]),
    )
    return HomingRun(tuple(places), pairs[:, 0], pairs[:, 1], directions, errors, stats)


def evaluate_alignment(
    places: Sequence[ManifestEntry],
    fingerprints: Sequence[Fingerprint],
    bin_width_m: float = 0.5,
    progress: bool = False,
) -> AlignmentRun:
    """For each compass of ``COMPASSES``, the rotation error of every same-room pair (figure 5.4).

    ``histogram`` is eq. 5.4 with 100 bins, ``smoothed`` toploc's smoothed compass, ``matched``
    the circular mean of matched features' bearing changes. Errors are against the manifest's
    heading difference (degrees, NaN where a compass gives no estimate).
    """
    pairs = same_room_pairs([p.room for p in places])
    if len(pairs) == 0:
        raise EvaluationError("no room has two places with positions: nothing to align")
    truth = _true_rotations(places, pairs)
    bearings = [f.bearings_rad for f in fingerprints]
    cache = PairCache(fingerprints, progress)
    cache.prepare(pairs)
    estimates: dict[str, list[float]] = {name: [] for name in COMPASSES}
    for i, j in pairs.tolist():
        both = len(bearings[i]) > 0 and len(bearings[j]) > 0
        for name in ("histogram", "smoothed"):
            estimates[name].append(
                bearing_shift_rad(bearings[j], bearings[i], method=name) if both else np.nan
            )
        estimates["matched"].append(
            matched_rotation_rad(bearings[i], bearings[j], cache.matches(i, j))
        )
    positions = positions_m(places)
    distances = np.linalg.norm(positions[pairs[:, 0]] - positions[pairs[:, 1]], axis=1)
    errors = {
        name: angular_error_deg(np.rad2deg(np.array(values)), np.rad2deg(truth))
        for name, values in estimates.items()
    }
    bins = {name: errors_by_distance(distances, e, bin_width_m) for name, e in errors.items()}
    return AlignmentRun(distances, errors, bins)
