"""Calibrating the likelihood on a map's own evidence: leave-one-out over its places.

Each stored place in turn is the query against the map without it (retrieval and verification
exactly as for a real query, :func:`localizer.evidence.place_evidence` with ``exclude``). Its
own room's best remaining place gives a same-room count, every other room's best place an
other-room count (:class:`localizer.likelihood_fit.CalibrationSamples`), and
:func:`localizer.likelihood_fit.fit_ratio_likelihood` turns them into the map's
:class:`~localizer.likelihood.RatioLikelihood`.

A stored place is a panorama taken where another panorama of the same room was not, so its
same-room counts are those of a query taken between the map's places (1.5–3 m from the nearest
one in a house); queries taken exactly at a stored place score higher, which the fit does not
see, so it errs on the side of caution.

Pure core: it works on a loaded map in memory.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np

from localizer.evidence import EvidenceParams, PlaceEvidence, place_evidence
from localizer.likelihood import RatioLikelihood, room_inliers
from localizer.likelihood_fit import CalibrationSamples, fit_ratio_likelihood
from localizer.loaded_map import LoadedMap
from localizer.lookalikes import alike_by_appearance, is_counterpart, partners_of

MAX_QUERIES = 60
"""Leave-one-out queries per calibration: about 20 s here, whatever the size of the map."""


def query_places(rooms: Sequence[str], max_queries: int) -> list[int]:
    """Indices of at most ``max_queries`` places to query, spread over the rooms in turn (every
    room gets its share before any gets more), in index order."""
    by_room: dict[str, list[int]] = {}
    for i, room in enumerate(rooms):
        by_room.setdefault(room, []).append(i)
    chosen: list[int] = []
    depth = 0
    while len(chosen) < min(max_queries, len(rooms)):
        for members in by_room.values():
            if depth < len(members) and len(chosen) < max_queries:
                # spread each room's picks over its places: 0, n/2, n/4, 3n/4, ...
                chosen.append(members[_spread_index(depth, len(members))])
        depth += 1
    return sorted(chosen)


def _spread_index(k: int, n: int) -> int:
    """The ``k``-th of ``n`` positions in bit-reversed order (a van der Corput sequence)."""
    order = sorted(range(n), key=lambda i: (_van_der_corput(i, n), i))
    return order[k]


def _van_der_corput(i: int, n: int) -> float:
    bits = max(n - 1, 1).bit_length()
    return int(format(i, f"0{bits}b")[::-1], 2) / (1 << bits)


@dataclass(frozen=True)
class LeftOut:
    """One leave-one-out query: the table index of the place left out, its room, the best
    count of every room of the map with the place as the query, and that evidence."""

    table_index: int
    room: str
    counts: dict[str, float]
    evidence: tuple[PlaceEvidence, ...]


def leave_one_out(
    loaded: LoadedMap,
    params: EvidenceParams | None = None,
    max_queries: int = MAX_QUERIES,
    *,
    count: str,
    places: Sequence[int] | None = None,
) -> Iterator[LeftOut]:
    """Per queried place (:func:`query_places`, or the table indices ``places``): the
    :class:`LeftOut` query, the best counts (``count``, see
    :func:`~localizer.likelihood.place_count`) taken when the place is the query and itself is
    left out (yielded one by one: this takes a while)."""
    params = params or EvidenceParams()
    table = loaded.table
    chosen = query_places(table.rooms, max_queries) if places is None else places
    for i in chosen:
        place_id = table.place_ids[i]
        evidence = place_evidence(
            table.fingerprint(i),
            table,
            params,
            loaded.index,
            exclude=int(place_id),
        )
        counts = room_inliers(evidence.places, loaded.rooms, count=count)
        per_room = dict(zip(loaded.rooms, (float(c) for c in counts), strict=True))
        yield LeftOut(i, table.rooms[i], per_room, evidence.places)


def counterpart_pairs(
    loaded: LoadedMap, queries: Sequence[LeftOut], pairs: Sequence[tuple[str, str]]
) -> tuple[tuple[int, int], ...]:
    """The counterparts (:func:`localizer.lookalikes.is_counterpart`) the leave-one-out found
    between the look-alike ``pairs`` of rooms: per query in one of them, the places of the
    other that its view verified on a counterpart's share of its keypoints (place ids, each pair
    once, lower id first). A place that was not queried (a map of more than ``MAX_QUERIES``
    places) may still be found as another's counterpart."""
    twins = partners_of(pairs)
    found: set[tuple[int, int]] = set()
    for query in queries:
        keypoints = int(loaded.table.keypoint_counts[query.table_index])
        own_id = int(loaded.table.place_ids[query.table_index])
        for item in query.evidence:
            if item.room in twins.get(query.room, ()) and is_counterpart(item.inliers, keypoints):
                found.add((min(own_id, item.place_id), max(own_id, item.place_id)))
    return tuple(sorted(found))


def calibrate(
    loaded: LoadedMap,
    params: EvidenceParams | None = None,
    prior: RatioLikelihood | None = None,
    on_query: Callable[[], None] | None = None,
    max_queries: int = MAX_QUERIES,
    declared: Sequence[tuple[str, str]] = (),
) -> tuple[RatioLikelihood, CalibrationSamples]:
    """The likelihood fitted on ``loaded``'s leave-one-out evidence, and the samples it was
    fitted on. ``on_query`` is called after each query (for a progress bar). ``declared``:
    look-alike pairs the user named, kept whatever the leave-one-out finds.

    With ``params.motion`` ``"auto"`` (the default) the leave-one-out runs with both relative
    pose models and keeps the one whose counts separate the rooms better
    (:func:`separation`): the planar model halves the chance inliers of other rooms when the
    camera is level, and loses own-room inliers when it is not (20 % at 1° of tilt, 40 % at
    2°, on the photo rooms), which this choice sees in the map's own panoramas.
    """
    params = params or EvidenceParams()
    motions = motions_to_try(params)
    fits = []
    for motion in motions:
        model, samples = _calibrate_with(
            loaded, replace(params, motion=motion), prior, on_query, max_queries, declared
        )
        fits.append((separation(samples), replace(model, motion=motion), samples))
    _, model, samples = max(fits, key=lambda fit: fit[0])  # ties: general, the first
    return model, samples


def motions_to_try(params: EvidenceParams) -> tuple[str, ...]:
    """The relative-pose models a calibration runs the leave-one-out with (both for ``auto``)."""
    return ("general", "planar") if params.motion == "auto" else (params.motion,)


def separation(samples: CalibrationSamples) -> float:
    """How far apart the same-room and other-room counts lie: the median of
    ``log(1 + same)`` less the 90th percentile of ``log(1 + other)`` (-inf without samples)."""
    if not len(samples.same_room) or not len(samples.other_room):
        return -np.inf
    same = float(np.median(np.log1p(samples.same_room)))
    return same - float(np.quantile(np.log1p(samples.other_room), 0.9))


def _calibrate_with(
    loaded: LoadedMap,
    params: EvidenceParams,
    prior: RatioLikelihood | None,
    on_query: Callable[[], None] | None,
    max_queries: int,
    declared: Sequence[tuple[str, str]] = (),
) -> tuple[RatioLikelihood, CalibrationSamples]:
    room_sizes = Counter(loaded.table.rooms)
    queries = []
    count = (prior or RatioLikelihood()).count
    for query in leave_one_out(loaded, params, max_queries, count=count):
        queries.append(query)
        if on_query is not None:
            on_query()
    samples = _samples(loaded, queries, room_sizes, declared)
    if samples.unasked_lookalikes:
        # a map of more rooms than queries: ask the rooms some query found nearly as good as
        # its own, so that a pair of twins is judged from both sides
        first_place = {room: i for i, room in reversed(list(enumerate(loaded.table.rooms)))}
        extra = [first_place[room] for room in samples.unasked_lookalikes[:max_queries]]
        for query in leave_one_out(loaded, params, count=count, places=sorted(extra)):
            queries.append(query)
        samples = _samples(loaded, queries, room_sizes, declared)
    model = fit_ratio_likelihood(samples, prior)
    told = tuple(sorted({(min(a, b), max(a, b)) for a, b in declared}))
    model = replace(model, declared=told)
    if not samples.lookalike_pairs:
        return model, samples
    counterparts = counterpart_pairs(loaded, queries, samples.lookalike_pairs)
    fit = dict(model.fit) | {"n_counterparts": float(len(counterparts))}
    model = replace(model, lookalikes=samples.lookalike_pairs, counterparts=counterparts, fit=fit)
    return model, samples


def best_matches(query: LeftOut) -> dict[str, tuple[int, int]]:
    """Per room, the (matches, inliers) of its place that gave the left-out view the most
    ratio-test matches (rooms the view reached no place of are left out)."""
    best: dict[str, tuple[int, int]] = {}
    for item in query.evidence:
        if item.matches > best.get(item.room, (-1, 0))[0]:
            best[item.room] = (int(item.matches), int(item.inliers))
    return best


def _samples(
    loaded: LoadedMap,
    queries: Sequence[LeftOut],
    room_sizes: Counter[str],
    declared: Sequence[tuple[str, str]],
) -> CalibrationSamples:
    """The calibration samples of ``queries``, with the rooms each view finds alike by their
    descriptors (:func:`localizer.lookalikes.alike_by_appearance`)."""
    alike = [
        alike_by_appearance(q.room, best_matches(q), room_sizes, loaded.edges) for q in queries
    ]
    return CalibrationSamples.from_queries(
        ((q.room, q.counts) for q in queries),
        room_sizes,
        alike=alike,
        declared=declared,
        edges=loaded.edges,
    )
