"""Active disambiguation: where to drive (by ALV homing) when the belief over rooms is ambiguous.

A policy picks the id of a stored place to home to; the caller homes there, captures, updates
the belief, adds the place to the context's ``tried`` and asks again while the belief stays
ambiguous (:func:`localizer.active.active_step`). Whatever a policy may ask the caller for (the
places tried, the robot's position, a view similarity computed on demand) comes in its
:class:`PolicyContext`, so the caller never needs to know which policy it runs.
Positions are metres in the frame of the place's own room (the map is topological: rooms do not
share a frame, so distances are only taken between places of the same room).

Two policies, registered by name in :data:`POLICIES`:

- ``"most-likely"`` (:class:`ThesisPolicy`), Goldhoorn 2008: the best-matching place of the most
  likely room.
- ``"separating"`` (:class:`DiscriminativePolicy`): the place of the most likely room whose
  stored view is least like the views of the rival rooms, minus a travel cost.

Pure core: no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from collections.abc import Set as AbstractSet
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar, Protocol

import numpy as np

from localizer.belief import RoomBelief
from localizer.likelihood import PlaceScore
from mapdb.records import Place


@dataclass(frozen=True, eq=False)
class PlaceSimilarity:
    """Similarity between stored places (computed by the caller with the evidence code).

    ``inliers[i, j]``: verified inliers when the panorama of ``place_ids[i]`` is the query and
    ``place_ids[j]`` the reference. The diagonal is the self-match (matching a stored panorama
    against itself, or its keypoint count): the scale that the other entries are divided by.
    """

    place_ids: tuple[int, ...]
    inliers: np.ndarray

    def __post_init__(self) -> None:
        matrix = np.asarray(self.inliers, dtype=float)
        n = len(self.place_ids)
        if matrix.shape != (n, n):
            raise ValueError(f"inliers has shape {matrix.shape}, expected ({n}, {n}) for place_ids")
        if len(set(self.place_ids)) != n:
            raise ValueError(f"place_ids must be unique, got {list(self.place_ids)}")
        if not np.all(np.isfinite(matrix)) or np.any(matrix < 0):
            raise ValueError("inliers must be finite and >= 0")
        object.__setattr__(self, "place_ids", tuple(int(p) for p in self.place_ids))
        object.__setattr__(self, "inliers", matrix)
        object.__setattr__(self, "_index", {p: i for i, p in enumerate(self.place_ids)})

    def index(self, place_id: int) -> int:
        """Row/column of ``place_id``; ``ValueError`` if the matrix does not cover it."""
        try:
            return self._index[place_id]  # type: ignore[attr-defined]
        except KeyError:
            raise ValueError(f"place {place_id} is not in the similarity matrix") from None


SimilarityFunction = Callable[[tuple[int, ...], tuple[int, ...]], PlaceSimilarity]
"""``similarity(rows, columns)``: a :class:`PlaceSimilarity` covering those place ids, in which
at least each row against itself and against every column is filled in (computed on demand)."""


@dataclass(frozen=True)
class PolicyContext:
    """What the caller knows beyond belief and evidence, and what a policy may ask it for.

    ``tried``: place ids already driven to. ``position_xy_m_by_room``: the robot's position
    under each room hypothesis, in that room's frame (e.g. from homing and odometry); where
    missing, the position of the room's best-matching place in the latest evidence is used.
    ``similarity``: stored-view similarity on demand (the separating policy needs it; matching
    stored views costs time, so a policy asks for just the entries it reads).
    ``lookalikes``: per room, the rooms the map's calibration found it looks like;
    ``counterparts``: per place id, the places of its look-alike rooms at the same spot of their
    frames (:mod:`localizer.lookalikes`).
    """

    tried: frozenset[int] = frozenset()
    position_xy_m_by_room: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    similarity: SimilarityFunction | None = None
    lookalikes: Mapping[str, frozenset[str]] = field(default_factory=dict)
    counterparts: Mapping[int, frozenset[int]] = field(default_factory=dict)

    def trying(self, place_id: int) -> PolicyContext:
        """The same context with ``place_id`` added to ``tried``."""
        return replace(self, tried=self.tried | {int(place_id)})


class Policy(Protocol):
    """Chooses the place to home to next."""

    name: ClassVar[str]

    def choose(
        self,
        belief: RoomBelief,
        evidence: Sequence[PlaceScore],
        places: Sequence[Place],
        context: PolicyContext,
    ) -> int | None:
        """Target place id, or ``None`` if every candidate has been tried.

        ``evidence``: the latest frame's per-place inliers. ``places``: the map's places.
        ``context``: the places tried so far and what the policy may ask the caller for.
        """
        ...


def _ranked_rooms(belief: Mapping[str, float], min_probability: float) -> list[str]:
    """Rooms from most to least likely (ties by name), keeping those above ``min_probability``."""
    ranked = sorted(belief.items(), key=lambda rp: (-rp[1], rp[0]))
    return [room for room, p in ranked if p > min_probability]


def _inliers_by_place(evidence: Iterable[PlaceScore]) -> dict[int, int]:
    best: dict[int, int] = {}
    for item in evidence:
        best[int(item.place_id)] = max(best.get(int(item.place_id), 0), int(item.inliers))
    return best


def _untried(places: Sequence[Place], room: str, tried: AbstractSet[int]) -> list[Place]:
    return [p for p in places if p.room == room and p.id not in tried]


def _target_room(
    probabilities: Mapping[str, float],
    places: Sequence[Place],
    tried: AbstractSet[int],
    min_room_probability: float,
) -> tuple[str, list[Place]] | None:
    """The most likely room (above ``min_room_probability``) with untried places, and those."""
    for room in _ranked_rooms(probabilities, min_room_probability):
        candidates = _untried(places, room, tried)
        if candidates:
            return room, candidates
    return None


def _rivals(
    probabilities: Mapping[str, float], room: str, min_rival_probability: float
) -> dict[str, float]:
    """The other rooms at least ``min_rival_probability`` likely, with their probabilities."""
    return {r: p for r, p in probabilities.items() if r != room and p >= min_rival_probability}


def separating_pairs(
    belief: Mapping[str, float],
    places: Sequence[Place],
    tried: AbstractSet[int],
    min_rival_probability: float = 0.02,
    min_room_probability: float = 0.0,
    lookalikes: Mapping[str, frozenset[str]] | None = None,
) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """``(candidates, rival places)``: the rows and columns of :class:`PlaceSimilarity` that
    :meth:`DiscriminativePolicy.choose` reads for ``belief`` (``{room: probability}``), so the
    similarity function need compute no more; both empty when there is nothing left to try.
    The candidates are the untried places of the most likely room and of its ``lookalikes``
    among the rivals (a drive to either twin's counterpart place tells them apart)."""
    target = _target_room(belief, places, tried, min_room_probability)
    if target is None:
        return (), ()
    room, candidates = target
    rivals = _rivals(belief, room, min_rival_probability)
    twins = set((lookalikes or {}).get(room, frozenset())) & set(rivals)
    candidates = candidates + [p for p in places if p.room in twins and p.id not in tried]
    columns = [p.id for p in places if p.room in rivals or (twins and p.room == room)]
    return tuple(c.id for c in candidates), tuple(columns)


@dataclass
class ThesisPolicy:
    """Goldhoorn 2008: home to the best place (most inliers in the latest evidence) of the most
    likely room not yet tried; when all of that room's places are tried, the next room.

    Rooms with probability <= ``min_room_probability`` are not candidates. Ties: lower place id.
    """

    name: ClassVar[str] = "most-likely"
    min_room_probability: float = 0.0

    def choose(
        self,
        belief: RoomBelief,
        evidence: Sequence[PlaceScore],
        places: Sequence[Place],
        context: PolicyContext,
    ) -> int | None:
        inliers = _inliers_by_place(evidence)
        target = _target_room(belief.as_dict(), places, context.tried, self.min_room_probability)
        if target is None:
            return None
        best = max(target[1], key=lambda p: (inliers.get(p.id, 0), -p.id))
        return best.id


@dataclass
class DiscriminativePolicy:
    """Home to the place of the most likely room whose view best separates it from the rivals.

    For each untried place ``c`` of the most likely room ``R`` (the next room once all of
    ``R``'s places are tried), with rivals ``r`` = the other rooms with probability
    >= ``min_rival_probability`` and weights ``w_r = p(r) / sum of rival p``:

        confusion(c)  = sum_r w_r * max_{q in places(r)} S[c, q] / S[c, c]     (clipped to [0, 1])
        separation(c) = 1 - confusion(c)
        score(c)      = separation(c) - travel_cost_per_m * distance_m(c)

    ``S`` is the context's :class:`PlaceSimilarity` (``S[c, c]`` the self-match; a place with
    ``S[c, c] = 0`` has separation 0). ``confusion`` is the fraction of ``c``'s own view that the
    best look-alike place of a rival room also explains: 1 for identical views (office_a/office_b
    away from their doors), lower where ``c`` sees something only ``R`` has (the view through the
    door). ``distance_m(c)``: from the robot's position under hypothesis ``R`` (context, else the
    best matching place of ``R`` in the evidence) to ``c``, 0 if either is unknown.
    ``travel_cost_per_m = 0.02``: one metre of travel is worth two percentage points of
    separation, so among equally separating places the nearest wins, and a place 5 m further
    must separate 10 points better. Ties: more inliers in the evidence, then lower place id.
    With no rivals it falls back to the nearest place (``separation`` is 1 for all).

    A rival that is a look-alike of ``R`` (context ``lookalikes``) adds its untried places to
    the candidates (scored with their own room as the hypothesis), and is compared on
    counterparts only: ``max_q`` runs over ``c``'s counterparts in it (context
    ``counterparts``), and a place without one has confusion 1 against it. A view of one twin
    taken where the other twin has no stored view shares little with the other twin's views,
    yet tells nothing about which twin the robot is in (on recorded maps every place rated
    0.75–0.94 without this, issue 19); at a counterpart the frame is compared with both twins'
    views of one spot. When no candidate separates at all (twins without counterparts), there
    is nothing to drive to: ``None``.
    """

    name: ClassVar[str] = "separating"
    min_rival_probability: float = 0.02
    travel_cost_per_m: float = 0.02
    min_room_probability: float = 0.0

    def choose(
        self,
        belief: RoomBelief,
        evidence: Sequence[PlaceScore],
        places: Sequence[Place],
        context: PolicyContext,
    ) -> int | None:
        if context.similarity is None:
            raise ValueError("the separating policy needs a view similarity in its context")
        probabilities = belief.as_dict()
        inliers = _inliers_by_place(evidence)
        rows, columns = separating_pairs(
            probabilities,
            places,
            context.tried,
            self.min_rival_probability,
            self.min_room_probability,
            context.lookalikes,
        )
        if not rows:
            return None
        by_id = {p.id: p for p in places}
        candidates = [by_id[place_id] for place_id in rows]
        similarity = context.similarity(rows, columns)
        separations = [
            self.separation(similarity, c.id, c.room, probabilities, places, context)
            for c in candidates
        ]
        if max(separations) <= 0.0:
            return None
        scored = [
            (
                separation
                - self.travel_cost_per_m
                * _distance_m(_position_in_room(c.room, places, inliers, context), c),
                inliers.get(c.id, 0),
                -c.id,
            )
            for separation, c in zip(separations, candidates, strict=True)
        ]
        return -max(scored)[2]

    def separation(
        self,
        similarity: PlaceSimilarity,
        place_id: int,
        room: str,
        belief: Mapping[str, float],
        places: Sequence[Place],
        context: PolicyContext | None = None,
    ) -> float:
        """``1 - confusion`` of ``place_id`` against the rivals of ``room`` (in [0, 1])."""
        row = similarity.inliers[similarity.index(place_id)]
        own = row[similarity.index(place_id)]
        rivals = _rivals(belief, room, self.min_rival_probability)
        total = sum(rivals.values())
        if total <= 0:
            return 1.0
        if own <= 0:
            return 0.0
        context = context or PolicyContext()
        twins = context.lookalikes.get(room, frozenset())
        counterparts = context.counterparts.get(place_id, frozenset())
        confusion = 0.0
        for rival, p in rivals.items():
            in_rival = [q.id for q in places if q.room == rival]
            if rival in twins:
                in_rival = [q for q in in_rival if q in counterparts]
                if not in_rival:
                    confusion += p / total  # a view no twin's view shares a spot with
                    continue
            columns = [similarity.index(q) for q in in_rival]
            if columns:
                confusion += (p / total) * min(1.0, float(row[columns].max()) / own)
        return 1.0 - confusion


def _distance_m(here_xy_m: tuple[float, float] | None, place: Place) -> float:
    """Metres from ``here_xy_m`` to ``place`` (same room frame), 0 if either is unknown."""
    if here_xy_m is None or place.xy_m is None:
        return 0.0
    return math.dist(here_xy_m, place.xy_m)


def _position_in_room(
    room: str,
    places: Sequence[Place],
    inliers: Mapping[int, int],
    context: PolicyContext,
) -> tuple[float, float] | None:
    """The robot's position under hypothesis ``room``: from context, else its best-matching
    place of that room in the evidence (``None`` if unknown)."""
    if room in context.position_xy_m_by_room:
        x_m, y_m = context.position_xy_m_by_room[room]
        return (float(x_m), float(y_m))
    in_room = [p for p in places if p.room == room and inliers.get(p.id, 0) > 0]
    if not in_room:
        return None
    return max(in_room, key=lambda p: (inliers[p.id], -p.id)).xy_m


POLICIES: dict[str, type[ThesisPolicy] | type[DiscriminativePolicy]] = {
    ThesisPolicy.name: ThesisPolicy,
    DiscriminativePolicy.name: DiscriminativePolicy,
}


def make_policy(name: str, **kwargs: Any) -> Policy:
    """The policy registered as ``name`` in :data:`POLICIES`, built with ``kwargs`` (its
    settings, e.g. ``min_rival_probability``)."""
    try:
        cls = POLICIES[name]
    except KeyError:
        raise ValueError(
            f"unknown disambiguation policy {name!r}; known: {', '.join(sorted(POLICIES))}"
        ) from None
    try:
        return cls(**kwargs)
    except TypeError as error:
        raise ValueError(f"cannot build policy {name!r} with {sorted(kwargs)}: {error}") from error
