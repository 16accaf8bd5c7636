"""Per-place evidence for a query panorama (Ramisa et al. 2006): matches, then verified inliers.

For every candidate place of the map (all of them, or the shortlist of a
:class:`~localizer.retrieval.PlaceIndex`), the query's descriptors are matched to the place's
with the ratio test (:func:`localizer.matching.match_descriptors`), and places with at least
``min_matches`` pairs are verified by an essential matrix on unit rays
(:func:`localizer.verification.verify`). The inlier count is the evidence; the recovered yaw
(``heading_query - heading_place``) is kept as a visual compass for homing.

How much of the query's horizon the inliers cover (:func:`azimuth_coverage`) is kept with the
count: a room seen through a door fills a narrow arc of the panorama however many inliers it
gives, the room the robot stands in surrounds it. The calibrated likelihood reads the count
weighted by that coverage (``PlaceEvidence.spread_inliers``).

The places come from a :class:`mapdb.records.PlaceStore`: stacked in memory, or read from the
map on demand (only the candidates' fingerprints are fetched, in one read). Each stored place is
read on its own camera (its fingerprint's), its keypoints' rays computed when it is verified.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from localizer.matching import DEFAULT_RATIO, match_descriptors
from localizer.retrieval import Shortlister
from localizer.verification import MIN_CORRESPONDENCES, VerificationParams, verify
from mapdb.records import Fingerprint, PlaceStore

MOTIONS: tuple[str, ...] = ("auto", "general", "planar")

COVERAGE_ARC_DEG = 30.0
"""Each inlier covers this arc of the query's horizon, centred on its azimuth (degrees)."""

ALL_ROUND_COVERAGE = 0.6
"""A place whose inliers cover at least this share of the query's horizon is seen all round:
the query stands in its room. A room seen through a door or an opening covers half the
horizon or less (a recorded ``building`` map: the corridor's one place from just inside an
office, 0.35 and 0.51; the bare house mapped one place per room: a bedroom from the hall and
the hall from a bedroom, 0.51 and 0.52; the living room on a bedroom's view, 0.25)."""


def azimuth_coverage(rays: np.ndarray, arc_deg: float = COVERAGE_ARC_DEG) -> float:
    """The share of the horizon (0 to 1) within ``arc_deg / 2`` of the azimuth of one of
    ``rays`` ((n, 3) unit rays, robot frame); 0 for no rays.

    The union of the arcs is the sum, over the azimuths in circular order, of the gap to the
    next one capped at ``arc_deg``: it does not change when the panorama is rolled in yaw.
    On the rendered house with one place per room, weighting the inliers by it took the
    confidently wrong answers of 50 queries off the map's places from 3 to 0 (doorway views:
    65 inliers through a bedroom's door against its own room's 16) and top-1 from 68 to 72 %
    (docs/results.md).
    """
    if not 0.0 < arc_deg <= 360.0:
        raise ValueError(f"arc_deg must be in (0, 360], got {arc_deg}")
    rays = np.asarray(rays, dtype=float).reshape(-1, 3)
    if len(rays) == 0:
        return 0.0
    azimuth_deg = np.sort(np.degrees(np.arctan2(rays[:, 1], rays[:, 0])) % 360.0)
    gaps_deg = np.diff(azimuth_deg, append=azimuth_deg[0] + 360.0)
    return float(min(np.minimum(gaps_deg, arc_deg).sum(), 360.0) / 360.0)


@dataclass(frozen=True)
class EvidenceParams:
    """How evidence is gathered.

    ``ratio``: Lowe's ratio for descriptor matching. ``min_matches``: places with fewer matches
    get 0 inliers without RANSAC. ``max_error_rad``: RANSAC inlier threshold (tangent Sampson
    error, rad). ``shortlist``: how many places an index hands to verification. ``seed``:
    RANSAC's seed. ``max_trials``: RANSAC's iteration cap per place. ``motion``: the relative
    pose model, ``"general"`` or ``"planar"`` (:class:`~localizer.verification.VerificationParams`),
    or ``"auto"``: the one the map's calibration chose (:mod:`localizer.calibration`), general
    for a map without one. ``threads``: candidates matched and verified at once (OpenCV's
    matcher and pycolmap's RANSAC release the GIL; each candidate's result does not depend on
    the others or on the order, so the evidence is the same with any count).
    """

    ratio: float = DEFAULT_RATIO
    min_matches: int = 10
    max_error_rad: float = 0.01
    shortlist: int = 10
    seed: int = 0
    max_trials: int = 300
    motion: str = "auto"
    threads: int = 2

    def __post_init__(self) -> None:
        if not 0 < self.ratio <= 1:
            raise ValueError(f"ratio must be in (0, 1], got {self.ratio!r}")
        if self.min_matches < MIN_CORRESPONDENCES:
            raise ValueError(
                f"min_matches must be >= {MIN_CORRESPONDENCES}, got {self.min_matches!r}"
            )
        if self.motion not in MOTIONS:
            raise ValueError(f"motion must be one of {MOTIONS}, got {self.motion!r}")
        if self.shortlist < 1:
            raise ValueError(f"shortlist must be >= 1, got {self.shortlist!r}")
        if self.threads < 1:
            raise ValueError(f"threads must be >= 1, got {self.threads!r}")
        self.verification()  # validates max_error_rad, seed and max_trials

    def verification(self) -> VerificationParams:
        """The matching :class:`VerificationParams`."""
        return VerificationParams(
            max_error_rad=self.max_error_rad,
            min_correspondences=self.min_matches,
            seed=self.seed,
            min_trials=min(100, self.max_trials),
            max_trials=self.max_trials,
            motion="general" if self.motion == "auto" else self.motion,
        )


@dataclass(frozen=True)
class PlaceEvidence:
    """Evidence for one stored place.

    ``matches``: ratio-test pairs; ``inliers``: pairs consistent with the essential matrix;
    ``yaw_rad``: ``heading_query - heading_place`` (nan without geometry); ``inlier_pairs`` (k, 2)
    int64 ``[query_keypoint, place_keypoint]``, the place's rows counted within that place;
    ``coverage``: :func:`azimuth_coverage` of the inliers' query rays (0 to 1);
    ``spread_inliers``: the inliers weighted by that share of the query's horizon (computed
    once here: the likelihood and the belief read it place by place).
    """

    place_id: int
    room: str
    matches: int
    inliers: int
    yaw_rad: float
    inlier_pairs: np.ndarray
    coverage: float
    spread_inliers: float = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "spread_inliers", self.inliers * self.coverage)


@dataclass(frozen=True)
class QueryEvidence:
    """Evidence for every verified place, most inliers first (ties: more matches, lower id).

    ``timing_ms``: ``"retrieval"`` (the index's shortlist; 0 for brute force) and
    ``"verification"`` (descriptor matching plus RANSAC over the candidates), in milliseconds.
    """

    places: tuple[PlaceEvidence, ...]
    timing_ms: dict[str, float]

    @property
    def best(self) -> PlaceEvidence | None:
        """The place with the most inliers, or None if no place was evaluated."""
        return self.places[0] if self.places else None


def _check_inputs(query: Fingerprint, table: PlaceStore) -> None:
    if query.detector != table.detector:
        raise ValueError(
            f"query fingerprint is {query.detector!r} but the table holds {table.detector!r}"
        )
    dim = table.descriptor_dim
    if len(table.place_ids) and query.n and query.descriptors.shape[1] != dim:
        raise ValueError(
            f"query descriptors have {query.descriptors.shape[1]} values, the table's {dim}"
        )


def evaluate_place(
    query: Fingerprint,
    query_rays: np.ndarray,
    place: Fingerprint,
    place_id: int,
    room: str,
    params: EvidenceParams,
) -> PlaceEvidence:
    """Match and verify the query (its unit rays ``query_rays``) against the stored
    fingerprint ``place`` of place ``place_id`` in ``room``."""
    pairs = match_descriptors(query.descriptors, place.descriptors, params.ratio)
    if len(pairs) < params.min_matches:
        empty = np.zeros((0, 2), dtype=np.int64)
        return PlaceEvidence(place_id, room, len(pairs), 0, float("nan"), empty, 0.0)
    result = verify(query_rays, place.rays(), pairs, params.verification())
    coverage = azimuth_coverage(query_rays[result.inlier_pairs[:, 0]])
    return PlaceEvidence(
        place_id, room, len(pairs), result.inliers, result.yaw_rad, result.inlier_pairs, coverage
    )


def place_evidence(
    query: Fingerprint,
    table: PlaceStore,
    params: EvidenceParams | None = None,
    index: Shortlister | None = None,
    exclude: int | None = None,
) -> QueryEvidence:
    """Evidence of ``query`` for the places of ``table`` (one detector).

    Brute force over every place when ``index`` is None; otherwise only the index's
    ``params.shortlist`` best places are verified (the others are left out of the result).
    An empty map gives no places; an empty query gives every candidate 0 matches.
    ``exclude`` (a place id) leaves that place out of retrieval and verification (leave-one-out
    evaluation of a map's own places). The candidates' fingerprints are read from ``table``
    in one call (for a store on disk: one read), before matching.
    """
    params = params or EvidenceParams()
    _check_inputs(query, table)
    t0 = time.perf_counter()
    left_out = None
    if exclude is not None:
        matches = np.flatnonzero(table.place_ids == exclude)
        left_out = int(matches[0]) if len(matches) else None
    if index is None:
        candidates = np.arange(len(table.place_ids))
        if left_out is not None:
            candidates = candidates[candidates != left_out]
    else:
        candidates = index.shortlist(query.descriptors, params.shortlist, left_out)
    t1 = time.perf_counter()
    query_rays = query.rays()
    stored = table.fingerprints(candidates) if index is not None else None

    def evaluate(k: int) -> PlaceEvidence:
        i = int(candidates[k])
        place = stored[k] if stored is not None else table.fingerprint(i)
        return evaluate_place(
            query, query_rays, place, int(table.place_ids[i]), table.rooms[i], params
        )

    if params.threads == 1 or len(candidates) < 2:
        evidence = [evaluate(k) for k in range(len(candidates))]
    else:
        with ThreadPoolExecutor(min(params.threads, len(candidates))) as pool:
            evidence = list(pool.map(evaluate, range(len(candidates))))
    t2 = time.perf_counter()
    evidence.sort(key=lambda e: (-e.inliers, -e.matches, e.place_id))
    timing = {"retrieval": (t1 - t0) * 1e3 if index is not None else 0.0}
    timing["verification"] = (t2 - t1) * 1e3
    return QueryEvidence(tuple(evidence), timing)
