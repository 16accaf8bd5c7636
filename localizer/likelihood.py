"""How one frame's evidence becomes a likelihood per room, calibrated on the map's own evidence.

For each room take ``n_r``, the count of its best place in the frame (0 if none of its places
was verified): by default the inliers weighted by the share of the query's horizon they cover
(``spread``, see :mod:`localizer.evidence`), for a model stored before that the raw inliers.
The question a count answers is: is this what the robot's own room gives, or what an unrelated
room gives by chance? :class:`RatioLikelihood` answers it with the ratio of the two densities,

    L_r = p(n_r | same room) / p(n_r | other room)
        = exp(intercept + slope * log(1 + n_r) + per_inlier * n_r),

fitted by :func:`fit_ratio_likelihood` as a class-balanced logistic regression of "same room"
on ``log(1 + n)`` and ``n`` (so the fitted log-odds are the log density ratio). The logarithm
carries the few-inlier range of bare rooms (7 against 25 inliers is a strong hint, 207 against
225 is not); the linear term lets a map whose other rooms reach hundreds of inliers by shared
texture say how much an absolute lead is worth there.
The samples come from leave-one-out over the map's places (:mod:`localizer.calibration`): each
place is a query against the map without it; its own room's best remaining place gives a
same-room count, every other room's best place an other-room count. This is the same idea as
RTAB-Map normalising a new image's scores by their distribution and FAB-MAP's explicit model of
unrelated places: the map tells what chance looks like in its own rooms.

Why this shape:

- The ratio does not depend on the number of rooms, so 15 rooms do not cap one frame's
  confidence (the softmax over rooms that toploc used before did: a 29-versus-7 margin gave
  25 %).
- Under "the robot is in room r", room r's count follows the same-room density and every other
  room's the other-room density, so the frame's likelihood of room r is proportional to
  ``L_r`` and a flat ``L`` means the frame cannot tell rooms apart.
- ``min_inliers``: a frame whose best count is below what the best of the unrelated rooms
  typically reaches by chance (the ``known_quantile``, by default the median, of the per-query
  maximum over the other rooms in the leave-one-out, rooms seen through a door left out; see
  :class:`CalibrationSamples`) says the panorama may come from no room of the map: its
  likelihood is flat and the state ``lost``. Above it, a room that is not in the
  map still has to beat every other room by the localized ratio on chance counts alone.
- A logistic fit with a ridge towards the defaults behaves with a dozen samples, and the log
  ratio is clipped at ``max_log_ratio`` (a frame can move the odds of two rooms by at most
  ``e^max_log_ratio``) so that one mis-verified frame can be outvoted later.

Pure core: numpy and scipy, no I/O.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np
from scipy.optimize import minimize
from scipy.special import softmax

LIKELIHOOD_SCHEMA = 1


class PlaceScore(Protocol):
    """Evidence for one stored place: its id, its room, the verified inlier count and that
    count weighted by the share of the query's horizon the inliers cover."""

    @property
    def place_id(self) -> int: ...

    @property
    def room(self) -> str: ...

    @property
    def inliers(self) -> int: ...

    @property
    def spread_inliers(self) -> float: ...


COUNTS: tuple[str, ...] = ("spread", "inliers")
"""What a likelihood reads of each place: ``spread`` (``spread_inliers``, the default since
the coverage was measured) or ``inliers`` (the raw count; maps calibrated before)."""


def place_count(item: PlaceScore, count: str) -> float:
    """``item``'s ``spread_inliers`` or ``inliers`` (``count``, one of :data:`COUNTS`)."""
    if count == "spread":
        return float(item.spread_inliers)
    if count == "inliers":
        return float(item.inliers)
    raise ValueError(f"count must be one of {COUNTS}, got {count!r}")


class Likelihood(Protocol):
    """A model turning the best inlier count per room into a likelihood per room."""

    @property
    def min_inliers(self) -> int:
        """Below this best count the frame says nothing (flat likelihood; state lost)."""
        ...

    @property
    def count(self) -> str:
        """What it reads of each place (one of :data:`COUNTS`)."""
        ...

    def from_room_inliers(self, room_inliers: np.ndarray) -> np.ndarray:
        """Likelihood per room (sums to 1) from the best inlier count per room, shape (N,)."""
        ...


def _check_counts(room_inliers: np.ndarray) -> np.ndarray:
    counts = np.asarray(room_inliers, dtype=float)
    if counts.ndim != 1 or counts.size == 0:
        raise ValueError(f"room_inliers must be a non-empty 1-D array, got shape {counts.shape}")
    if not np.all(np.isfinite(counts)) or np.any(counts < 0):
        raise ValueError(f"room_inliers must be finite and >= 0, got {counts.tolist()}")
    return counts


@dataclass(frozen=True)
class RatioLikelihood:
    """The calibrated likelihood of the module docstring.

    ``intercept``, ``slope``, ``per_inlier``: the log density ratio
    ``intercept + slope * log(1 + n) + per_inlier * n``.
    ``motion``: the relative-pose model the counts were verified with (``general`` or
    ``planar``; the calibration picks the one that separates the map's rooms better).
    ``min_inliers``: below this best count the frame is flat and ``lost``. ``max_log_ratio``:
    the clip of the log ratio. ``fit``: how it was fitted (sample sizes, medians and quantiles
    of the counts; empty for the defaults), for ``toploc map info`` and the docs.
    ``count``: what is counted of each place (:data:`COUNTS`); a model stored before the
    coverage existed reads ``inliers``. ``lookalikes``: the pairs of look-alike rooms the
    leave-one-out found, ``counterparts``: the pairs of their places (ids) at the same spot of
    both (:mod:`localizer.lookalikes`; both empty for a model stored before them);
    ``declared``: the pairs the user said look alike (``toploc map lookalike``), always among
    ``lookalikes`` and kept by every calibration.

    The defaults (used for a map that cannot be calibrated: fewer than two places in every room,
    and the prior the fit is pulled towards) are the fit on the bare rendered ``house`` (35
    equirectangular places 1.5 m apart) on raw inlier counts, before the contrast equalisation,
    with ``per_inlier = 1/30``: where two rooms both match strongly (look-alike rooms, whose
    difference lies in what the door shows), 30 more inliers multiply the odds by e. The
    leave-one-out barely constrains this term (it sets look-alikes apart), so the prior carries
    much of it. The old softmax's 1/15 made two confident mistakes on a house map with one
    place per room (a bedroom query won by the living room, 22 inliers against 7); 1/30 made
    none there, and in the look-alike offices it ended 11 of 12 kidnappings localized, against
    6 of 12 with 1/15 (docs/results.md).
    They were kept for the ``spread`` count: on the dense house its same-room and other-room
    counts barely overlap, so a refit follows whatever prior it starts from (-4.4 + 1.17 log +
    0.020 n from these, flatter again from that); on the house with one place per room these
    localized 21 of the 36 right answers and that refit 15, neither with a wrong one.
    ``min_inliers = 6``: ten inliers at random azimuths cover 1 - (11/12)^10 = 58 % of the
    horizon, so the 10 chance inliers of a real bare house (its own room gave 7–28, the others
    5–10) count about 6.
    """

    intercept: float = -6.9
    slope: float = 2.5
    per_inlier: float = 1.0 / 30.0
    min_inliers: int = 6
    max_log_ratio: float = 25.0
    motion: str = "general"
    fit: Mapping[str, float] = field(default_factory=dict)
    count: str = "spread"
    lookalikes: tuple[tuple[str, str], ...] = ()
    counterparts: tuple[tuple[int, int], ...] = ()
    declared: tuple[tuple[str, str], ...] = ()

    def __post_init__(self) -> None:
        if self.count not in COUNTS:
            raise ValueError(f"count must be one of {COUNTS}, got {self.count!r}")
        if not all(math.isfinite(v) for v in (self.intercept, self.slope, self.per_inlier)):
            raise ValueError(f"intercept, slope and per_inlier must be finite, got {self}")
        if self.slope < 0 or self.per_inlier < 0:
            raise ValueError(
                f"slope and per_inlier must be >= 0 (more inliers never count against), got {self}"
            )
        if self.min_inliers < 0:
            raise ValueError(f"min_inliers must be >= 0, got {self.min_inliers}")
        if self.motion not in ("general", "planar"):
            raise ValueError(f"motion must be general or planar, got {self.motion!r}")
        if not self.max_log_ratio > 0:
            raise ValueError(f"max_log_ratio must be positive, got {self.max_log_ratio}")

    def log_ratio(self, inliers: np.ndarray | float) -> np.ndarray:
        """``log p(n | same room) / p(n | other room)`` for inlier counts ``n``, clipped."""
        n = np.asarray(inliers, dtype=float)
        value = self.intercept + self.slope * np.log1p(n) + self.per_inlier * n
        return np.clip(value, -self.max_log_ratio, self.max_log_ratio)

    def from_room_inliers(self, room_inliers: np.ndarray) -> np.ndarray:
        """Likelihood per room (sums to 1) from the best inlier count per room, shape (N,)."""
        return self.from_counts(room_inliers)

    def from_counts(
        self,
        room_inliers: np.ndarray,
        aliased: Sequence[Sequence[int]] = (),
        compared: Sequence[Sequence[int]] = (),
        read: np.ndarray | None = None,
    ) -> np.ndarray:
        """Likelihood per room (sums to 1) from the best count per room, shape (N,); the rooms
        of each ``aliased`` group of look-alikes (room indices, :mod:`localizer.lookalikes`)
        are weighed as equally likely, those of each ``compared`` group at most
        :data:`MAX_TWIN_LOG_RATIO` apart, as their counts ``read`` on counterparts (default:
        ``room_inliers``) say (:func:`lookalike_log_ratios`)."""
        counts = _check_counts(room_inliers)
        if counts.max() < self.min_inliers:
            return np.full(counts.size, 1.0 / counts.size)
        read_ratios = None if read is None else self.log_ratio(_check_counts(read))
        return softmax(lookalike_log_ratios(self.log_ratio(counts), aliased, compared, read_ratios))

    def to_json(self) -> dict[str, Any]:
        """JSON-ready dict (stored in the map)."""
        return {
            "schema": LIKELIHOOD_SCHEMA,
            "model": "ratio",
            "intercept": self.intercept,
            "slope": self.slope,
            "per_inlier": self.per_inlier,
            "min_inliers": self.min_inliers,
            "max_log_ratio": self.max_log_ratio,
            "motion": self.motion,
            "fit": dict(self.fit),
            "count": self.count,
            "lookalikes": [list(pair) for pair in self.lookalikes],
            "counterparts": [list(pair) for pair in self.counterparts],
            "declared_lookalikes": [list(pair) for pair in self.declared],
        }

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> RatioLikelihood:
        """Inverse of :meth:`to_json`; ``ValueError`` naming what is wrong."""
        if data.get("schema") != LIKELIHOOD_SCHEMA or data.get("model") != "ratio":
            raise ValueError(
                f"not a ratio likelihood of schema {LIKELIHOOD_SCHEMA}: "
                f"schema {data.get('schema')!r}, model {data.get('model')!r}"
            )
        try:
            return cls(
                intercept=float(data["intercept"]),
                slope=float(data["slope"]),
                per_inlier=float(data.get("per_inlier", 0.0)),
                min_inliers=int(data["min_inliers"]),
                max_log_ratio=float(data["max_log_ratio"]),
                motion=str(data.get("motion", "general")),
                fit={str(k): float(v) for k, v in dict(data.get("fit", {})).items()},
                count=str(data.get("count", "inliers")),
                lookalikes=tuple((str(a), str(b)) for a, b in list(data.get("lookalikes", []))),
                counterparts=tuple((int(a), int(b)) for a, b in list(data.get("counterparts", []))),
                declared=tuple(
                    (str(a), str(b)) for a, b in list(data.get("declared_lookalikes", []))
                ),
            )
        except (KeyError, TypeError, ValueError) as error:
            raise ValueError(f"bad stored likelihood {dict(data)}: {error}") from error


@dataclass(frozen=True)
class CalibrationSamples:
    """Leave-one-out evidence of a map: per query place, its own room's best count among the
    other places (``same_room``, only for rooms with two or more places), every other room's best
    count (``other_room``), and the largest of those left to chance per query (``max_other``).

    A room that explains a query nearly as well as the query's own room, or better (at least
    ``lookalike_fraction`` of the own room's count and at least ``lookalike_min_inliers``), is a
    look-alike of it for that view: the twin bedrooms of the ``house`` world, or the living room
    seen through the hall's open door. Its count is what a same-room view gives, not chance:
    it is counted in ``n_lookalike``, left out of ``other_room`` and ``max_other``, and stands
    for the own room when it is higher (leaving a place out leaves its twin's identical view in
    the map, while the own room's nearest view is a whole place spacing away). Look-alike rooms
    cannot be told apart by that view; both get a high likelihood and the belief stays ambiguous
    until the robot drives to a telling place.

    ``max_other`` is the chance level the lost test reads: the best count among the other rooms
    left to chance. A room with at least ``lookalike_min_inliers``, at least a tenth of the
    own room's count (``chance_fraction``) and at least twice the median of the query's other
    rooms stands out of them: it is seen, through a door or a window, not matched by chance.
    It stays an other-room sample for the ratio but is left out of ``max_other``. Chance that
    lifts every room (shared texture: all of them at 22–40) does not stand out and stays the
    chance level. In a bare map, where chance gives 5–10 and the own room 7–28, nothing
    changes. Without this, a house map whose hall and living room are mapped whole and the
    other rooms by one place each (its hall places see both bedrooms through their doors)
    measured a chance level of 33 and said ``lost`` for 16 of 50 queries, the small rooms' own
    counts being 13–18; with it 4 (docs/results.md).
    """

    same_room: np.ndarray
    other_room: np.ndarray
    max_other: np.ndarray
    n_lookalike: int = 0
    lookalike_pairs: tuple[tuple[str, str], ...] = ()
    """The look-alike rooms found, each pair once (sorted names): rooms each of which explained
    at least half of the other's queries nearly as well as their own room
    (:meth:`from_queries`' ``pair_fraction``)."""
    unasked_lookalikes: tuple[str, ...] = ()
    """Rooms some query found nearly as good as its own but that no query came from: whether
    they are look-alikes is unknown until one of their places is queried too."""
    pair_tests: tuple[str, ...] = ()
    """Per entry of ``lookalike_pairs``, the test that made it a pair: ``"declared"`` (the
    user named it), ``"count"`` (each room's count in the other's views, alone enough),
    ``"outdone"`` (one room outdid the other's own room in its views), ``"standout"`` (one
    stood out of every other room in half of the other's views, or each in half of the
    other's) or ``"appearance"``
    (only with the rooms alike by their descriptors)."""

    @classmethod
    def from_queries(
        cls,
        queries: Iterable[tuple[str, Mapping[str, float]]],
        room_sizes: Mapping[str, int],
        lookalike_min_inliers: float = 20.0,
        lookalike_fraction: float = 0.8,
        chance_fraction: float = 0.1,
        pair_fraction: float = 0.5,
        pair_min_inliers: float = 8.0,
        pair_chance_factor: float = 4.0,
        standout_min_inliers: float = 5.0,
        standout_factor: float = 2.0,
        standout_fraction: float = 0.25,
        far_standout_min_inliers: float = 10.0,
        far_standout_factor: float = 4.0,
        far_standout_fraction: float = 0.1,
        alike: Sequence[Collection[str]] = (),
        declared: Iterable[tuple[str, str]] = (),
        edges: Iterable[tuple[str, str]] = (),
    ) -> CalibrationSamples:
        """From ``(query's room, {room: best inlier count})`` per query; ``room_sizes`` (places
        per room) says whether the query's room had another place to match.

        Two rooms are a look-alike pair when each finds the other in at least half of its
        queries: at ``pair_fraction`` of the query's own count or more, at least
        ``pair_chance_factor`` times the median of the query's other rooms and at least
        ``pair_min_inliers`` (the bare house's twin bedrooms, recorded three places each,
        explain each other's views at 8–50 spread inliers, their own rooms at 6–21, every
        other room at most 2), or among the rooms that look like the query's by their
        descriptors (``alike``, one collection per query in order;
        :func:`localizer.lookalikes.alike_by_appearance`). That is looser than a query's own
        twin test (``lookalike_fraction``): a room recorded at places a metre apart explains
        its own views better than the twin does (office_a 209 spread inliers, office_b 110 on a
        map recorded with three places per office, every other room at most 13), yet the twin
        explains every one of them. Rooms joined by one of ``edges`` are not paired by their
        counts: each sees the other through the door, and on a map of two places per room the
        one view by the door is half of its room's views (maps recorded on one drive paired
        the house's hall with a bathroom and the building's corridor with an office: the
        belief could not tell them apart, and no route check could end in them). Pairs the
        user ``declared`` are pairs whatever the views say (rooms the map lacks left out). A
        pair's counts in each other's views are never chance counts, however low (its places
        far from the view's spot).

        One side is enough when another room **outdoes** the own room: in at least half of a
        room's queries (the room having another place to match), a room not joined to it by
        one of ``edges`` (no door between them) reaches the pair bar and at least the own
        room's count, which is not 0 (a view its own room did not verify at all is outdone by
        any chance count). Only a twin explains a view better than the view's own room does from
        beyond a wall; the twin's own views need not return it, as its places may stand nearer
        each other than to the first room's (a recorded house: bedroom_b explained
        bedroom_a's views at 9 and 5 spread inliers against their own room's 5 and 5, while
        bedroom_b's views found their own room at 40 and 34, bedroom_a at 11 and 4).

        One side is enough, too, when a room **stands out** in at least half of a room's
        queries (that room having another place to match and verifying the view, the other
        room asked too), and when each of two rooms stands out in at least half of the other's
        queries (rooms of one place have no own count to weigh a twin against): with no door
        between them, at least ``standout_min_inliers``, ``standout_fraction`` of the own
        room's count and ``standout_factor`` times every room but the two. A room seen
        through a door is joined to the view's room by it (left out), one seen through two
        doors is seen with the room between them; a twin stands out alone (bare twin bedrooms
        recorded three places each: bedroom_b's views found bedroom_a at 11.7, 12.1 and 4.2
        spread inliers against their own room's 25, 23 and 14, no other room above 2.3;
        bedroom_a's views found bedroom_b at 15.0, 2.9 and 2.2).
        A room also stands out **far above chance** at a lower share of the own room's count:
        at least ``far_standout_min_inliers``, ``far_standout_fraction`` of the own room's
        count and ``far_standout_factor`` times every room but the two
        (office_a recorded three places a metre apart explains its own views at 96–113 spread
        inliers, and office_b stands at 14–25 in each of them, no other room above 4; left
        unpaired, 10 of 20 kidnappings into the offices came out sure and wrong, the twin whose
        place stood nearer the robot winning by up to four times the count). A house recorded
        on one drive with one place per room (world seed 19): the bedrooms' views found each
        other at 12.7 and 8.0 spread inliers, every other room at most 0.9, just under the
        mutual count test's ``pair_min_inliers``; unpaired, 4 of 20 kidnappings ended sure and
        wrong, the robot reading the twin at 63–79 spread inliers from the spot of its place."""
        queries = list(queries)
        flagged: Counter[tuple[str, str]] = Counter()
        by_count: Counter[tuple[str, str]] = Counter()
        outdone: Counter[tuple[str, str]] = Counter()
        standing_out: Counter[tuple[str, str]] = Counter()
        both_ways: Counter[tuple[str, str]] = Counter()
        adjacent = {frozenset(edge) for edge in edges}
        asked: Counter[str] = Counter()
        for k, (own_room, best) in enumerate(queries):
            own = float(best.get(own_room, 0.0))
            seen_alike = alike[k] if k < len(alike) else ()
            asked[own_room] += 1
            rooms = [r for r in room_sizes if r != own_room]
            chances = medians_without_each([float(best.get(r, 0.0)) for r in rooms])
            rest = largest_without_each([float(best.get(r, 0.0)) for r in rooms])
            for room, chance, others_max in zip(rooms, chances, rest, strict=True):
                bar = max(pair_min_inliers, pair_fraction * own, pair_chance_factor * chance)
                count = float(best.get(room, 0.0))
                counted = count >= bar
                by_count[(own_room, room)] += counted
                # rooms joined by a door see each other through it: their counts pair them
                # neither from one side nor mutually (appearance leaves them out too)
                through_door = frozenset((own_room, room)) in adjacent
                # one side may pair only a view its own room verified, from beyond a wall
                one_side = own > 0 and room_sizes.get(own_room, 0) >= 2 and not through_door
                outdone[(own_room, room)] += one_side and counted and count >= own
                near = count >= max(
                    standout_min_inliers, standout_factor * others_max, standout_fraction * own
                )
                far = count >= max(
                    far_standout_min_inliers,
                    far_standout_factor * others_max,
                    far_standout_fraction * own,
                )
                stands = not through_door and (near or far)
                standing_out[(own_room, room)] += one_side and stands
                both_ways[(own_room, room)] += stands
                if (counted and not through_door) or room in seen_alike:
                    flagged[(own_room, room)] += 1
        # twins explain most of each other's views; a room seen through a door explains only
        # the views near it (on the dense house, hall and living room against the bedrooms)
        told = {(min(a, b), max(a, b)) for a, b in declared if a != b}
        one_sided = {
            (min(a, b), max(a, b)) for (a, b), n in outdone.items() if n > 0 and n >= 0.5 * asked[a]
        }
        standouts = {
            (min(a, b), max(a, b))
            for (a, b), n in standing_out.items()
            if n > 0 and n >= 0.5 * asked[a] and asked[b] > 0  # b judged from its views too
        } | set(mutual_pairs(both_ways, asked))
        pairs = tuple(
            sorted(
                set(mutual_pairs(flagged, asked))
                | one_sided
                | standouts
                | {(a, b) for a, b in told if a in room_sizes and b in room_sizes}
            )
        )
        counted_pairs = set(mutual_pairs(by_count, asked))
        tests = tuple(
            "declared"
            if pair in told
            else "count"
            if pair in counted_pairs
            else "outdone"
            if pair in one_sided
            else "standout"
            if pair in standouts
            else "appearance"
            for pair in pairs
        )
        paired = {frozenset(pair) for pair in pairs}
        same: list[float] = []
        other: list[float] = []
        max_other: list[float] = []
        n_lookalike = 0
        for own_room, best in queries:
            own = float(best.get(own_room, 0.0))
            has_own = room_sizes.get(own_room, 0) >= 2
            bar = max(lookalike_min_inliers, lookalike_fraction * own)
            twins = [r for r in room_sizes if r != own_room and float(best.get(r, 0.0)) >= bar]
            not_chance = set(twins) | {r for r in room_sizes if frozenset((own_room, r)) in paired}
            others = [
                float(best.get(room, 0.0))
                for room in room_sizes
                if room != own_room and room not in not_chance
            ]
            lookalikes = [float(best.get(room, 0.0)) for room in twins]
            if lookalikes:
                n_lookalike += len(lookalikes)
                own = max(own, *lookalikes)
            if has_own or lookalikes:
                same.append(own)
            other += others
            typical = float(np.median(others)) if others else 0.0
            seen_bar = max(lookalike_min_inliers, chance_fraction * own, 2.0 * typical)
            unseen = [count for count in others if count < seen_bar]
            if unseen:
                max_other.append(max(unseen))
        unasked = sorted({b for _, b in flagged if asked[b] == 0})
        return cls(
            np.array(same),
            np.array(other),
            np.array(max_other),
            n_lookalike,
            pairs,
            tuple(unasked),
            tests,
        )


def largest_without_each(values: Sequence[float]) -> np.ndarray:
    """For each entry of ``values``, the largest of all the other entries (0.0 where there
    are none)."""
    x = np.asarray(values, dtype=float)
    if len(x) <= 1:
        return np.zeros(len(x))
    order = np.argsort(x)
    top, second = x[order[-1]], x[order[-2]]
    out = np.full(len(x), top)
    out[order[-1]] = second
    return out


def medians_without_each(values: Sequence[float]) -> np.ndarray:
    """For each entry of ``values``, the median of all the other entries (0.0 where there are
    none), in one sort: ``out[i] == np.median(values[:i] + values[i+1:])``. The calibration
    asks, for every query and every room, what the remaining rooms give by chance; at 10,000
    places (494 rooms) a median per room per query took 12 s of the calibration, this 0.2 s."""
    x = np.asarray(values, dtype=float)
    n = len(x)
    if n <= 1:
        return np.zeros(n)
    order = np.argsort(x, kind="stable")
    ranked = x[order]
    position = np.empty(n, dtype=int)
    position[order] = np.arange(n)
    m = n - 1  # entries left once one is removed

    def kth_left(k: int) -> np.ndarray:
        """The k-th smallest of the entries left when each one in turn is removed."""
        return np.where(k < position, ranked[k], ranked[k + 1])

    if m % 2:
        return kth_left(m // 2)
    return 0.5 * (kth_left(m // 2 - 1) + kth_left(m // 2))


def mutual_pairs(
    flagged: Mapping[tuple[str, str], int], asked: Mapping[str, int]
) -> tuple[tuple[str, str], ...]:
    """The pairs of rooms each of which found the other in at least half of its queries
    (``flagged[(a, b)]``: queries from ``a`` that found ``b``; ``asked[a]``: queries from
    ``a``), each pair once as sorted names. A room never queried pairs with nothing (on a map
    of more rooms than queries that vacuous "half of none" joined 277 pairs over 494 rooms)."""
    return tuple(
        sorted(
            {
                (min(a, b), max(a, b))
                for (a, b), n in flagged.items()
                if n > 0
                and flagged.get((b, a), 0) > 0  # b was asked, and found a too
                and n >= 0.5 * asked.get(a, 0)
                and flagged[(b, a)] >= 0.5 * asked.get(b, 0)
            }
        )
    )


INLIER_SCALE = 100.0
"""The linear feature is ``n / INLIER_SCALE`` in the fit, so both features are of order 1."""


def _balanced_logistic_loss(
    params: np.ndarray, x: np.ndarray, y: np.ndarray, w: np.ndarray, prior: np.ndarray, ridge: float
) -> float:
    z = params[0] + x @ params[1:]
    # log(1 + exp(-z)) for y = 1 and log(1 + exp(z)) for y = 0, computed stably
    loss = np.where(y > 0, np.logaddexp(0.0, -z), np.logaddexp(0.0, z))
    return float(np.sum(w * loss) + ridge * np.sum((params - prior) ** 2))


def fit_ratio_likelihood(
    samples: CalibrationSamples,
    prior: RatioLikelihood | None = None,
    ridge: float = 1.0,
    known_quantile: float = 0.5,
) -> RatioLikelihood:
    """Fit the log density ratio to ``samples`` (see the module docstring).

    Each class carries half the weight whatever its size, so the fitted log-odds are the log
    density ratio. ``ridge`` pulls intercept and slope towards ``prior`` (the defaults) like that
    many pseudo-samples. ``min_inliers`` is one more than the ``known_quantile`` of the
    per-query maximum other-room count (never below the prior's). Without same-room samples
    (every room has one place) the ratio cannot be fitted: ``prior`` is returned with the
    measured chance level.
    """
    prior = prior or RatioLikelihood()
    same, other = samples.same_room, samples.other_room
    chance = float(np.quantile(samples.max_other, known_quantile)) if len(samples.max_other) else 0
    min_inliers = max(prior.min_inliers, math.floor(chance) + 1)
    if len(same) == 0 or len(other) == 0:
        # one place per room: no same-room count to fit on, but chance is still measured
        return replace(prior, min_inliers=min_inliers, fit={"max_other_quantile": chance})
    counts = np.concatenate([same, other])
    x = np.column_stack([np.log1p(counts), counts / INLIER_SCALE])
    y = np.concatenate([np.ones(len(same)), np.zeros(len(other))])
    w = np.concatenate([np.full(len(same), 0.5 / len(same)), np.full(len(other), 0.5 / len(other))])
    start = np.array([prior.intercept, prior.slope, prior.per_inlier * INLIER_SCALE])
    scale = ridge / (len(same) + len(other))
    result = minimize(
        _balanced_logistic_loss,
        start,
        args=(x, y, w, start, scale),
        method="L-BFGS-B",
        bounds=[(None, None), (0.0, None), (0.0, None)],
    )
    intercept, slope, per_hundred = (float(v) for v in result.x)
    fit = {
        "n_same_room": float(len(same)),
        "n_other_room": float(len(other)),
        "n_lookalike": float(samples.n_lookalike),
        "same_room_median": float(np.median(same)),
        "other_room_median": float(np.median(other)),
        "other_room_p95": float(np.quantile(other, 0.95)),
        "max_other_quantile": chance,
        "known_quantile": known_quantile,
    }
    return replace(
        prior,
        intercept=intercept,
        slope=slope,
        per_inlier=per_hundred / INLIER_SCALE,
        min_inliers=min_inliers,
        fit=fit,
    )


MAX_TWIN_LOG_RATIO = math.log(4.0)
"""The most one frame read on counterparts moves the odds of two look-alike rooms: a factor of
4, so that no single frame makes twins sure (localized asks for 10) and two frames from
different spots can. Counterparts recorded by hand stand a few decimetres apart, and a frame
near one of them favours its room by that offset alone (0.2 m cost a third of the inliers in
``building``; on held-out recorded maps, uncapped, 2 of 20 first looks came out sure and
wrong that way)."""


def lookalike_log_ratios(
    log_ratios: np.ndarray,
    aliased: Sequence[Sequence[int]] = (),
    compared: Sequence[Sequence[int]] = (),
    read: np.ndarray | None = None,
) -> np.ndarray:
    """Per-room log ratios with each ``aliased`` group of look-alike rooms (room indices) at
    its best member's: the frame says the group is there as strongly as its best count says,
    and nothing about which of its rooms (their counts say which has a stored place nearer the
    robot). In each ``compared`` group each room falls below the group's best by as much as
    its log ratio ``read`` on counterparts falls below the reading's best (default
    ``log_ratios``), at most :data:`MAX_TWIN_LOG_RATIO`: the reading says which twin, the best
    count how strongly the group. Rooms in no group keep their log ratio."""
    out = np.array(log_ratios, dtype=float)
    read = out.copy() if read is None else np.asarray(read, dtype=float)
    for group in aliased:
        members = list(group)
        out[members] = out[members].max()
    for group in compared:
        members = list(group)
        below = np.minimum(read[members].max() - read[members], MAX_TWIN_LOG_RATIO)
        out[members] = out[members].max() - below
    return out


def room_inliers(evidence: Iterable[PlaceScore], rooms: Sequence[str], *, count: str) -> np.ndarray:
    """Best count per room (order of ``rooms``), 0 for a room without evidence; ``count``
    says which (:func:`place_count`).

    Raises ``ValueError`` for evidence naming a room not in ``rooms`` or a negative count.
    """
    index = {room: i for i, room in enumerate(rooms)}
    best = np.zeros(len(index), dtype=float)
    for item in evidence:
        if item.room not in index:
            raise ValueError(
                f"evidence for place {item.place_id} names room {item.room!r}, "
                f"which is not one of {list(index)}"
            )
        value = place_count(item, count)
        if not value >= 0:  # negative or NaN
            raise ValueError(f"evidence for place {item.place_id} has {value:g} {count}")
        i = index[item.room]
        best[i] = max(best[i], value)
    return best


def room_likelihood(
    evidence: Iterable[PlaceScore], rooms: Sequence[str], model: Likelihood | None = None
) -> np.ndarray:
    """Likelihood per room (order of ``rooms``, sums to 1, every entry > 0) for one frame;
    ``model`` defaults to :class:`RatioLikelihood`'s defaults."""
    model = model or RatioLikelihood()
    return model.from_room_inliers(room_inliers(evidence, rooms, count=model.count))


def max_inliers(evidence: Iterable[PlaceScore], *, count: str) -> float:
    """The largest count (:func:`place_count`) of one frame's evidence (0 if there is none);
    ``ValueError`` for a negative or NaN one."""
    values = [place_count(item, count) for item in evidence]
    if not all(value >= 0 for value in values):
        raise ValueError(f"evidence counts must be >= 0, got {values}")
    return max(values, default=0.0)
