"""Where `best` homing (``pose-vote``) loses: the axis of the verified translation, or its sign.

For each dataset (a folder that ``toploc eval homing`` reads), every ordered same-room pair is
evaluated as ``toploc eval homing`` does (the same features, matches and verified poses), and
this prints:

- the eq. 5.6 score of ``thesis`` (true headings), of ``best``, and of the verified axis with
  the sign the truth would give (``oracle sign``: how much a better sign could gain; pairs
  without geometry take the matched ALV);
- the score of ``best`` with the general 5-point pose instead of the planar one (``general
  pose``: ``best`` before session 46; :data:`localizer.visual_homing.HOMING_VERIFICATION`);
- the score of ``best`` without the keypoint sizes (``without sizes``: the distance vote from
  the elevations alone, as on a map stored before schema version 5) and with the four votes
  of sessions 28-43 (``four votes``: the elevations' vote counted as one of four, beside the
  cheirality and the two ALVs, a tie going its way);
- on the pairs whose axis lies within 30° of the truth (either sign), how often each sign
  vote is right: the cheirality above the floor, the matched ALV, the ALV of all features
  turned by the pose's yaw (:func:`localizer.visual_homing.signed_pose_direction_rad`), and
  the distance vote (:func:`localizer.verification.distance_vote`) whatever its t-statistic
  and where it counts (``counted``: from :data:`localizer.visual_homing.DISTANCE_VOTE_MIN_T`);
- the median error of the verified pose's yaw against the headings' difference (degrees).

With ``--per-pair``, also each pair whose ``best`` error exceeds the thesis's: the places'
distance apart, the verification's inliers, the two methods' errors and the axis's, and each
sign vote (+1: the axis as verified, -1: its opposite; the distance vote with its
t-statistic) beside the sign the truth gives.

With ``--tilt-deg T``, every other place's panorama (odd rows of the manifest) is rolled by T
degrees about its forward axis before the poses are solved (its rays turned: a camera mounted
or held out of level; the thesis method reads only bearings and stays as it is).

Run: ``python benchmarks/bench_homing_signs.py [--per-pair] [--tilt-deg T] DATASET [DATASET
...]``; docs/homing.md names the datasets it was run on.
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
from localizer.verification import (
    VerificationParams,
    cheirality_sign,
    distance_vote,
    home_direction_rad,
)
from localizer.visual_homing import (
    DISTANCE_VOTE_MIN_T,
    HOMING_VERIFICATION,
    signed_pose_direction_rad,
)
from mapdb.records import Fingerprint
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


class TiltedPairCache(PairCache):
    """A :class:`PairCache` whose odd-numbered panoramas are rolled by ``tilt_deg`` degrees
    about their forward (x) axis."""

    def __init__(
        self, fingerprints: list[Fingerprint], tilt_deg: float, params: VerificationParams
    ) -> None:
        super().__init__(fingerprints, params=params)
        c, s = math.cos(math.radians(tilt_deg)), math.sin(math.radians(tilt_deg))
        self.roll = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])

    def rays(self, i: int) -> np.ndarray:
        rays = super().rays(i)
        return rays @ self.roll.T if i % 2 else rays


def run(dataset: Path, per_pair: bool = False, tilt_deg: float = 0.0) -> None:
    places = load_places(dataset)
    fingerprints = extract_fingerprints(
        [dataset / p.image for p in places], FeatureSettings(), workers=2
    )
    cache = TiltedPairCache(fingerprints, tilt_deg, HOMING_VERIFICATION)
    pairs = same_room_pairs([p.room for p in places])
    positions, headings = positions_m(places), headings_rad(places)
    truth = true_home_direction_rad(positions[pairs[:, 0]], positions[pairs[:, 1]])

    def errors(directions: np.ndarray) -> np.ndarray:
        return pair_errors_deg(directions, headings[pairs[:, 0]], truth)

    thesis = errors(_home_directions("thesis", places, cache, pairs))
    best = _home_directions("pose-vote", places, cache, pairs)
    best_errors = errors(best)
    general_cache = TiltedPairCache(fingerprints, tilt_deg, VerificationParams(motion="general"))
    general = errors(_home_directions("pose-vote", places, general_cache, pairs))
    matched = _home_directions("matched-alv", places, cache, pairs)
    alvs = [alv_from_bearings(f.bearings_rad) for f in fingerprints]
    oracle, without_sizes, four_votes = best.copy(), best.copy(), best.copy()
    votes: dict[str, list[bool]] = {
        "cheirality": [],
        "matched ALV": [],
        "ALV, pose yaw": [],
        "distance": [],
        "counted": [],
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
        rays_i, rays_j = cache.rays(i), cache.rays(j)
        cheirality = cheirality_sign(v, rays_i, rays_j)
        sizes_i, sizes_j = (
            fingerprints[i].keypoint_sizes_rad(),
            fingerprints[j].keypoint_sizes_rad(),
        )
        distance, statistic = distance_vote(v, rays_i, rays_j, sizes_i, sizes_j)
        elevation, elevation_t = distance_vote(v, rays_i, rays_j)
        elevation = elevation if abs(elevation_t) >= DISTANCE_VOTE_MIN_T else 0
        without_sizes[k] = signed_pose_direction_rad(
            v, matched[k], alvs[i], alvs[j], cheirality, elevation
        )
        rough = sum(side_of(d, axis) for d in (matched[k], alv_rad))
        total = cheirality + elevation + rough
        flip = total < 0 or (total == 0 and (elevation or cheirality) < 0)
        four_votes[k] = axis + math.pi if flip else axis
        if per_pair and best_errors[k] > thesis[k]:
            print(
                f"  {places[i].room} {i}->{j}: {np.hypot(*(positions[i] - positions[j])):.1f} m, "
                f"{v.inliers} inliers; thesis {thesis[k]:.1f} deg, best {best_errors[k]:.1f} deg, "
                f"axis {min(both):.1f} deg; truth {right_sign(both):+d}, cheirality "
                f"{cheirality:+d}, distance {distance:+d} (t {statistic:.1f}), matched ALV "
                f"{side_of(matched[k], axis):+d}, ALV with the pose's yaw "
                f"{side_of(alv_rad, axis):+d}"
            )
        if min(both) > GOOD_AXIS_DEG:
            continue
        right = right_sign(both)
        votes["cheirality"].append(cheirality == right)
        if distance != 0:
            votes["distance"].append(distance == right)
            if abs(statistic) >= DISTANCE_VOTE_MIN_T:
                votes["counted"].append(distance == right)
        for name, d in (("matched ALV", matched[k]), ("ALV, pose yaw", alv_rad)):
            if math.isfinite(d):
                votes[name].append(side_of(d, axis) == right)
    shares = ", ".join(f"{name} {np.mean(v):.0%} of {len(v)}" for name, v in votes.items() if v)
    name = f"{dataset.name} rolled {tilt_deg:g} deg" if tilt_deg else dataset.name
    print(
        f"{name}: {len(pairs)} pairs; thesis {score(thesis):.3f}, best "
        f"{score(best_errors):.3f}, general pose {score(general):.3f}, oracle sign "
        f"{score(errors(oracle)):.3f}, without sizes "
        f"{score(errors(without_sizes)):.3f}, four votes {score(errors(four_votes)):.3f}; "
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
    parser.add_argument(
        "--tilt-deg", type=float, default=0.0, help="roll every other panorama by this (degrees)"
    )
    args = parser.parse_args()
    for dataset in args.datasets:
        run(dataset, args.per_pair, args.tilt_deg)


if __name__ == "__main__":
    main()
