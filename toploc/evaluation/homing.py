"""Homing and alignment on a panorama dataset (Goldhoorn 2008, sections 5.4 and 5.6-5.7).

The adapter of :mod:`homing.evaluation`: reads a dataset folder (``manifest.csv`` + images),
extracts one fingerprint per image (once per run; optionally in a *spawn* process pool), and
evaluates every ordered pair of places of the same room (positions are in each room's frame).

Methods (``METHODS``): ``"thesis"`` is the ALV of all feature bearings with the headings of the
manifest (section 5.6). The others work without headings:

* ``"alv-compass"``: the thesis's ALV, the rotation from the smoothed bearing-histogram compass;
* ``"matched-alv"``: the ALV of descriptor-matched features only, the rotation from the circular
  mean of their bearing changes;
* ``"matched-vote"``: the home direction in the most wedges of matched features (see
  :func:`homing.evaluation.wedge_vote_direction_rad`), the rotation as for ``matched-alv``.

The matched methods fall back to ``"alv-compass"`` for a pair whose matches give no home
vector (no match, or a single one: aligning it zeroes the vector). MSER on these panoramas finds
few features, so this happens for MSER pairs.

``"best"`` is the one measured best on the rendered lab, square and corridor (``BEST_METHOD``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from homing.alv import alv_from_bearings, angular_error_deg
from homing.compass import bearing_shift_rad
from homing.evaluation import (
    DistanceBin,
    HomingStats,
    alv_home_directions_rad,
    compass_rotation_rad,
    errors_by_distance,
    homing_statistics,
    matched_alv_direction_rad,
    matched_rotation_rad,
    pair_errors_deg,
    true_home_direction_rad,
    wedge_vote_direction_rad,
)
from localizer.features import ExtractionParams, extract
from localizer.matching import match_descriptors
from localizer.panorama_io import read_panorama
from mapdb.dataset import ManifestEntry, read_manifest
from mapdb.records import Fingerprint
from mapdb.workers import spawn_process_pool

METHODS: tuple[str, ...] = ("thesis", "best", "alv-compass", "matched-alv", "matched-vote")
BEST_METHOD = "matched-alv"
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


def _extract_one(path: Path, params: ExtractionParams) -> Fingerprint:
    import cv2

    cv2.setNumThreads(1)  # one process per core already
    return extract(read_panorama(path), params)


def extract_fingerprints(
    paths: Sequence[Path], params: ExtractionParams, workers: int = 1, progress: bool = False
) -> list[Fingerprint]:
    """One fingerprint per image, in order; a pool of ``workers`` spawned processes if > 1.

    An unreadable image raises :class:`localizer.panorama_io.PanoramaError` naming the file.
    """
    bar = tqdm(total=len(paths), desc=f"extract {params.detector}", disable=not progress)
    try:
        if workers <= 1:
            results = []
            for path in paths:
                results.append(extract(read_panorama(path), params))
                bar.update()
            return results
        with spawn_process_pool(workers) as pool:
            futures = [pool.submit(_extract_one, path, params) for path in paths]
            results = []
            for future in futures:
                results.append(future.result())
                bar.update()
            return results
    finally:
        bar.close()


def same_room_pairs(rooms: Sequence[str]) -> np.ndarray:
    """Ordered pairs ``(k, 2)`` ``[here, home]`` of distinct indices whose rooms are equal."""
    r = np.asarray(rooms)
    same = (r[:, None] == r[None, :]) & ~np.eye(len(r), dtype=bool)
    return np.argwhere(same).astype(np.int64)


def _unordered_matches(
    fingerprints: Sequence[Fingerprint], pairs: np.ndarray, progress: bool
) -> dict[tuple[int, int], np.ndarray]:
    """Matches ``[row in i, row in j]`` for each unordered pair ``(i < j)`` of ``pairs``."""
    keys = sorted({(min(a, b), max(a, b)) for a, b in pairs.tolist()})
    return {
        (i, j): match_descriptors(fingerprints[i].descriptors, fingerprints[j].descriptors)
        for i, j in tqdm(keys, desc="match", disable=not progress)
    }


def _oriented(matches: dict[tuple[int, int], np.ndarray], a: int, b: int) -> np.ndarray:
    """Matches ``[row in a, row in b]``."""
    return matches[(a, b)] if a < b else matches[(b, a)][:, ::-1]


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


def _home_directions(
    method: str,
    places: Sequence[ManifestEntry],
    fingerprints: Sequence[Fingerprint],
    pairs: np.ndarray,
    progress: bool,
) -> np.ndarray:
    bearings = [f.bearings_rad for f in fingerprints]
    if method == "thesis":
        alvs = np.array([alv_from_bearings(b) if len(b) else [0.0, 0.0] for b in bearings])
        directions = alv_home_directions_rad(
            alvs[pairs[:, 0]], alvs[pairs[:, 1]], _true_rotations(places, pairs)
        )
        empty = np.array([len(bearings[i]) == 0 or len(bearings[j]) == 0 for i, j in pairs])
        return np.where(empty, np.nan, directions)
    if method == "alv-compass":
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
    estimate = {"matched-alv": matched_alv_direction_rad, "matched-vote": wedge_vote_direction_rad}
    matches = _unordered_matches(fingerprints, pairs, progress)
    out = np.empty(len(pairs))
    for k, (i, j) in enumerate(pairs.tolist()):
        m = _oriented(matches, i, j)
        rotation = matched_rotation_rad(bearings[i], bearings[j], m)
        out[k] = estimate[method](bearings[i], bearings[j], m, rotation)
    fallback = np.isnan(out)
    if np.any(fallback):  # no match, or one (its rotation zeroes the home vector): thesis ALV
        chosen = pairs[fallback]
        out[fallback] = _home_directions("alv-compass", places, fingerprints, chosen, False)
    return out


def evaluate_homing(
    places: Sequence[ManifestEntry],
    fingerprints: Sequence[Fingerprint],
    method: str = "thesis",
    progress: bool = False,
) -> HomingRun:
    """Home vectors for every ordered same-room pair with ``method``, and their statistics.

    Raises :class:`EvaluationError` for an unknown method, a length mismatch, no room with two
    places, or (``thesis``) a pair without headings.
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
    directions = _home_directions(method, places, fingerprints, pairs, progress)
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
    matches = _unordered_matches(fingerprints, pairs, progress)
    estimates: dict[str, list[float]] = {name: [] for name in COMPASSES}
    for i, j in pairs.tolist():
        both = len(bearings[i]) > 0 and len(bearings[j]) > 0
        for name in ("histogram", "smoothed"):
            estimates[name].append(
                bearing_shift_rad(bearings[j], bearings[i], method=name) if both else np.nan
            )
        estimates["matched"].append(
            matched_rotation_rad(bearings[i], bearings[j], _oriented(matches, i, j))
        )
    positions = positions_m(places)
    distances = np.linalg.norm(positions[pairs[:, 0]] - positions[pairs[:, 1]], axis=1)
    errors = {
        name: angular_error_deg(np.rad2deg(np.array(values)), np.rad2deg(truth))
        for name, values in estimates.items()
    }
    bins = {name: errors_by_distance(distances, e, bin_width_m) for name, e in errors.items()}
    return AlignmentRun(distances, errors, bins)
