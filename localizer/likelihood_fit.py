"""Fitting the ratio likelihood (:class:`localizer.likelihood.RatioLikelihood`) to a map's
leave-one-out evidence: the samples (:class:`CalibrationSamples`: per query place, its own
room's best count, every other room's, the best left to chance, and the look-alike rooms found
on the way) and the class-balanced logistic fit of "same room" on ``log(1 + n)`` and ``n``
(:func:`fit_ratio_likelihood`). :mod:`localizer.calibration` runs the leave-one-out and calls
these; :mod:`localizer.likelihood` says why the likelihood has this shape.

Pure core: numpy and scipy, no I/O.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import minimize

from localizer.likelihood import RatioLikelihood


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
        room's count and ``standout_factor`` times every room but the two (when each stands
        out in the other's views: every room but the two beyond the view's walls, for the
        rooms its doors open onto are seen, not chance; one side, where one view of two may
        pair, keeps them in its bar). A room seen
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
        wrong, the robot reading the twin at 63–79 spread inliers from the spot of its place.
        A building recorded so (world seed 103): office_a's view found office_b at 7.3 and the
        corridor, through its door, at 7.0, office_b's found office_a at 13.8 and the corridor
        at 5.5; with the corridor in the bar the offices went unpaired, and 7 of 20 robots
        kidnapped into them were sure of the wrong one at their first look (0.97–1.0). A
        building recorded two places per room (world seed 107): one of the storage room's two
        views found the kitchen at 7.6, the corridor and the seminar room through its doors at
        6.5 and 5.4; one side keeping them in its bar, the kitchen is no twin of it."""
        queries = list(queries)
        flagged: Counter[tuple[str, str]] = Counter()
        by_count: Counter[tuple[str, str]] = Counter()
        outdone: Counter[tuple[str, str]] = Counter()
        standing_out: Counter[tuple[str, str]] = Counter()
        both_ways: Counter[tuple[str, str]] = Counter()
        adjacent = {frozenset(edge) for edge in edges}
        asked: Counter[str] = Counter()

        def stands_out(count: float, own: float, others_max: float) -> bool:
            near = count >= max(
                standout_min_inliers, standout_factor * others_max, standout_fraction * own
            )
            far = count >= max(
                far_standout_min_inliers,
                far_standout_factor * others_max,
                far_standout_fraction * own,
            )
            return near or far

        for k, (own_room, best) in enumerate(queries):
            own = float(best.get(own_room, 0.0))
            seen_alike = alike[k] if k < len(alike) else ()
            asked[own_room] += 1
            rooms = [r for r in room_sizes if r != own_room]
            counts = [float(best.get(r, 0.0)) for r in rooms]
            chances = medians_without_each(counts)
            rest = largest_without_each(counts)
            doors = [frozenset((own_room, r)) in adjacent for r in rooms]
            rest_beyond = largest_without_each(
                [0.0 if door else c for c, door in zip(counts, doors, strict=True)]
            )
            for room, count, chance, others_max, beyond_max, through_door in zip(
                rooms, counts, chances, rest, rest_beyond, doors, strict=True
            ):
                bar = max(pair_min_inliers, pair_fraction * own, pair_chance_factor * chance)
                counted = count >= bar
                by_count[(own_room, room)] += counted
                # rooms joined by a door (through_door) see each other through it: their counts
                # pair them neither from one side nor mutually (appearance leaves them out too)
                # one side may pair only a view its own room verified, from beyond a wall
                one_side = own > 0 and room_sizes.get(own_room, 0) >= 2 and not through_door
                outdone[(own_room, room)] += one_side and counted and count >= own
                if not through_door:
                    standing_out[(own_room, room)] += one_side and stands_out(
                        count, own, others_max
                    )
                    both_ways[(own_room, room)] += stands_out(count, own, beyond_max)
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
