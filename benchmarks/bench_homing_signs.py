"""Where `best` homing (``pose-vote``) loses: the axis of the verified translation, or its sign.

For each dataset (a folder that ``toploc eval homing`` reads), every ordered same-room pair is
evaluated as ``toploc eval homing`` does (the same features, matches and verified poses), and
this prints:

- the eq. 5.6 score of ``thesis`` (true headings), of ``best``, and of the verified axis with
  the sign the truth would give (``oracle sign``: how much a better sign could gain; pairs
  without geometry take the matched ALV);
- on the pairs whose axis lies within 30° of the truth (either sign), how often each of
  ``best``'s sign votes is right: the cheirality above the floor, the matched ALV, the ALV of
  all features turned by the pose's yaw and the elevations' change
  (:func:`localizer.visual_homing.signed_pose_direction_rad`);
- the median error of the verified pose's yaw against the headings' difference (degrees);
- the score of ``best`` with the cheirality vote weighted by each inlier's parallax
  (``parallax-weighted``: inliers near the axis, whose parallax is within the noise, count
  less; with the three votes of before session 28), a variant measured here and not adopted;
- how often the elevation vote (:func:`localizer.verification.elevation_vote`, whatever its
  t-statistic) is right, and the score of ``best`` without it (``without the elevation
  vote``: the three votes of ``best`` before session 28).

With ``--per-pair``, also each pair whose ``best`` error exceeds the thesis's: the places'
distance apart, the verification's inliers, the two methods' errors and the axis's, and each
sign vote (+1: the axis as verified, -1: its opposite; the elevation vote with its
t-statistic, counted only from :data:`localizer.visual_homing.ELEVATION_VOTE_MIN_T`) beside
the sign the truth gives.

Run: ``python benchmarks/bench_homing_signs.py [--per-pair] DATASET [DATASET ...]``;
docs/homing.md names the datasets it was run on.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from homing.alv import alv_from_bearings
from homing.bearings import wrap_angle_rad
from homing.home_directions import alv_home_directions_rad
from homing.thesis.evaluation import pair_errors_deg, true_home_direction_rad
from localizer.planar import triangulated_depths
from localizer.verification import (
    FLOOR_ELEVATION_DEG,
    Verification,
    cheirality_sign,
    elevation_vote,
    home_direction_rad,
)
from localizer.visual_homing import signed_pose_direction_rad
from toploc.evaluation.homing import (
    FeatureSettings,
    PairCache,
    _home_directions,
    extract_fingerprints,
    headings_rad,
    load_places,
    positions_m,
    same_room_pairs,
)

GOOD_AXIS_DEG = 30.0


def score(errors_deg: np.ndarray) -> float:
    """Eq. 5.6: 1 - mean |error| / 180°, a pair without a direction counted as 90°."""
    return float(1.0 - np.mean(np.abs(np.where(np.isnan(errors_deg), 90.0, errors_deg))) / 180.0)


def weighted_cheirality(v: Verification, rays_query: np.ndarray, rays_place: np.ndarray) -> int:
    """The cheirality vote with each inlier above the floor weighted by its parallax (radians
    between its two rays, the place's turned into the query frame); all inliers on a tie."""
    if v.rotation is None or v.translation_dir is None or len(v.inlier_pairs) == 0:
        return 0
    x_query = rays_query[v.inlier_pairs[:, 0]]
    x_place = rays_place[v.inlier_pairs[:, 1]] @ v.rotation.T
    depth_place, depth_query = triangulated_depths(x_place, x_query, v.translation_dir)
    front = (depth_place > 0) & (depth_query > 0)
    behind = (depth_place < 0) & (depth_query < 0)
    parallax = np.arccos(np.clip(np.einsum("ij,ij->i", x_place, x_query), -1.0, 1.0))
    z_min = math.sin(math.radians(FLOOR_ELEVATION_DEG))
    above = (x_query[:, 2] > z_min) & (x_place[:, 2] > z_min)
    for keep in (above, np.ones_like(above)):
        total = float(((front.astype(float) - behind) * parallax)[keep].sum())
        if total != 0.0:
            return 1 if total > 0 else -1
    return 1


def run(dataset: Path, per_pair: bool = False) -> None:
    places = load_places(dataset)
    fingerprints = extract_fingerprints(
        [dataset / p.image for p in places], FeatureSettings(), workers=2
    )
    cache = PairCache(fingerprints)
    pairs = same_room_pairs([p.room for p in places])
    positions, headings = positions_m(places), headings_rad(places)
    truth = true_home_direction_rad(positions[pairs[:, 0]], positions[pairs[:, 1]])

    def errors(directions: np.ndarray) -> np.ndarray:
        return pair_errors_deg(directions, headings[pairs[:, 0]], truth)

    thesis = errors(_home_directions("thesis", places, cache, pairs))
    best = _home_directions("pose-vote", places, cache, pairs)
    best_errors = errors(best)
    matched = _home_directions("matched-alv", places, cache, pairs)
    alvs = [alv_from_bearings(f.bearings_rad) for f in fingerprints]
    oracle, weighted, without_elevation = best.copy(), best.copy(), best.copy()
    votes: dict[str, list[bool]] = {
        "cheirality": [],
        "matched ALV": [],
        "ALV, pose yaw": [],
        "elevation": [],
    }
    yaw_errors_deg: list[float] = []
    for k, (i, j) in enumerate(pairs.tolist()):
        v = cache.verification(i, j)
        if math.isfinite(v.yaw_rad):
            off = wrap_angle_rad(v.yaw_rad - (headings[i] - headings[j]))
            yaw_errors_deg.append(abs(math.degrees(float(off))))
        axis = home_direction_rad(v)
        if math.isnan(axis):
            oracle[k] = matched[k]
            continue
        both = errors_one(axis, headings[i], truth[k])
        oracle[k] = axis if both[0] <= both[1] else axis + math.pi
        alv_rad = math.nan
        if math.isfinite(v.yaw_rad):
            alv_rad = float(
                alv_home_directions_rad(alvs[i][None], alvs[j][None], np.array([-v.yaw_rad]))[0]
            )
        rough = [d for d in (matched[k], alv_rad) if math.isfinite(d)]
        side = weighted_cheirality(v, cache.rays(i), cache.rays(j))
        alvs_say = sum(side_of(d, axis) for d in rough)
        total = side + alvs_say
        flip = total < 0 or (total == 0 and side < 0)
        weighted[k] = axis + math.pi if flip else axis
        cheirality = cheirality_sign(v, cache.rays(i), cache.rays(j))
        elevation, statistic = elevation_vote(v, cache.rays(i), cache.rays(j))
        without_elevation[k] = signed_pose_direction_rad(
            v, matched[k], alvs[i], alvs[j], cheirality
        )
        if per_pair and best_errors[k] > thesis[k]:
            print(
                f"  {places[i].room} {i}->{j}: {np.hypot(*(positions[i] - positions[j])):.1f} m, "
                f"{v.inliers} inliers; thesis {thesis[k]:.1f} deg, best {best_errors[k]:.1f} deg, "
                f"axis {min(both):.1f} deg; truth {right_sign(both):+d}, cheirality "
                f"{cheirality:+d}, elevation {elevation:+d} (t {statistic:.1f}), matched ALV "
                f"{side_of(matched[k], axis):+d}, ALV with the pose's yaw "
                f"{side_of(alv_rad, axis):+d}"
            )
        if min(both) > GOOD_AXIS_DEG:
            continue
        right = right_sign(both)
        votes["cheirality"].append(cheirality == right)
        if elevation != 0:
            votes["elevation"].append(elevation == right)
        for name, d in (("matched ALV", matched[k]), ("ALV, pose yaw", alv_rad)):
            if math.isfinite(d):
                votes[name].append(side_of(d, axis) == right)
    shares = ", ".join(f"{name} {np.mean(v):.0%}" for name, v in votes.items() if v)
    print(
        f"{dataset.name}: {len(pairs)} pairs; thesis {score(thesis):.3f}, best "
        f"{score(best_errors):.3f}, oracle sign {score(errors(oracle)):.3f}, parallax-weighted "
        f"{score(errors(weighted)):.3f}, without the elevation vote "
        f"{score(errors(without_elevation)):.3f}; "
        f"yaw error median {np.median(yaw_errors_deg):.1f} deg; "
        f"{len(votes['cheirality'])} pairs with the axis within "
        f"{GOOD_AXIS_DEG:.0f} deg, votes right: {shares}"
    )


def right_sign(both_deg: np.ndarray) -> int:
    """+1 where the axis as verified errs less than its opposite (:func:`errors_one`), else -1."""
    return 1 if both_deg[0] <= both_deg[1] else -1


def side_of(direction_rad: float, axis_rad: float) -> int:
    """The side of ``axis_rad`` ``direction_rad`` lies on (+1 within 90° of it, -1 beyond), 0
    for no direction (NaN)."""
    return int(np.sign(math.cos(direction_rad - axis_rad))) if math.isfinite(direction_rad) else 0


def errors_one(axis_rad: float, heading_rad: float, truth_rad: float) -> np.ndarray:
    """The error (degrees) of ``axis_rad`` and of its opposite for one pair."""
    return pair_errors_deg(
        np.array([axis_rad, axis_rad + math.pi]),
        np.array([heading_rad, heading_rad]),
        np.array([truth_rad, truth_rad]),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("datasets", nargs="+", type=Path)
    parser.add_argument(
        "--per-pair", action="store_true", help="also each pair where best errs more than thesis"
    )
    args = parser.parse_args()
    for dataset in args.datasets:
        run(dataset, args.per_pair)


if __name__ == "__main__":
    main()
