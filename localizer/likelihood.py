"""How one frame's evidence becomes a likelihood per room, calibrated on the map's own evidence.

For each room take ``n_r``, the count of its best place in the frame (0 if none of its places
was verified): by default the inliers weighted by the share of the query's horizon they cover
(``spread``, see :mod:`localizer.evidence`), for a model stored before that the raw inliers.
The question a count answers is: is this what the robot's own room gives, or what an unrelated
room gives by chance? :class:`RatioLikelihood` answers it with the ratio of the two densities,

    L_r = p(n_r | same room) / p(n_r | other room)
        = exp(intercept + slope * log(1 + n_r) + per_inlier * n_r),

fitted by :func:`~localizer.likelihood_fit.fit_ratio_likelihood` as a class-balanced logistic
regression of "same room" on ``log(1 + n)`` and ``n`` (so the fitted log-odds are the log
density ratio). The logarithm carries the few-inlier range of bare rooms (7 against 25 inliers
is a strong hint, 207 against 225 is not); the linear term lets a map whose other rooms reach
hundreds of inliers by shared texture say how much an absolute lead is worth there.
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
  :class:`~localizer.likelihood_fit.CalibrationSamples`) says the panorama may come from no
  room of the map: its likelihood is flat and the state ``lost``. Above it, a room that is not
  in the map still has to beat every other room by the localized ratio on chance counts alone.
- A logistic fit with a ridge towards the defaults behaves with a dozen samples, and the log
  ratio is clipped at ``max_log_ratio`` (a frame can move the odds of two rooms by at most
  ``e^max_log_ratio``) so that one mis-verified frame can be outvoted later.

Pure core: numpy and scipy, no I/O.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
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
        pairs: Collection[tuple[int, int]] | None = None,
    ) -> np.ndarray:
        """Likelihood per room (sums to 1) from the best count per room, shape (N,); the rooms
        of each ``aliased`` group of look-alikes (room indices, :mod:`localizer.lookalikes`)
        are weighed as likely as their look-alikes in it (``pairs``; None: as equally likely),
        those of each ``compared`` group at most :data:`MAX_TWIN_LOG_RATIO` apart, as their
        counts ``read`` on counterparts (default: ``room_inliers``) say
        (:func:`lookalike_log_ratios`)."""
        counts = _check_counts(room_inliers)
        if counts.max() < self.min_inliers:
            return np.full(counts.size, 1.0 / counts.size)
        read_ratios = None if read is None else self.log_ratio(_check_counts(read))
        log_ratios = self.log_ratio(counts)
        return softmax(lookalike_log_ratios(log_ratios, aliased, compared, read_ratios, pairs))

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
    pairs: Collection[tuple[int, int]] | None = None,
) -> np.ndarray:
    """Per-room log ratios with each room of an ``aliased`` group of look-alike rooms (room
    indices) at the best of its own and its look-alikes' in the group (``pairs``, room indices;
    None: every two rooms of a group are look-alikes, and each room is at the group's best):
    the frame says a room is there as strongly as the best count of a room that looks like it,
    and nothing about which of them (their counts say which has a stored place nearer the
    robot). A room is lifted by its own look-alikes only, not by theirs: a storage room whose
    walls share photographs with office_a, and office_a's twin office_b, make one group, but a
    frame that shows office_b at 326 spread inliers, office_a at 25 and the storage room at 1
    says nothing for the storage room that office_a's 25 does not (world seed 137's building,
    two places per room: lifted to the group's best, the storage room, which robots in
    office_a could neither reach nor check by a route, held 0.10-0.38 of the belief to the
    end, and 4 of 20 robots put in office_a ended ambiguous). In
    each ``compared`` group each room falls below the group's best by as much as its log ratio
    ``read`` on counterparts falls below the reading's best (default ``log_ratios``), at most
    :data:`MAX_TWIN_LOG_RATIO`: the reading says which twin, the best count how strongly the
    group. Rooms in no group keep their log ratio."""
    raw = np.array(log_ratios, dtype=float)
    out = raw.copy()
    read = raw.copy() if read is None else np.asarray(read, dtype=float)
    alike = None if pairs is None else {frozenset(pair) for pair in pairs}
    for group in aliased:
        for room in group:
            lifting = [
                other
                for other in group
                if other == room or alike is None or frozenset((room, other)) in alike
            ]
            out[room] = raw[lifting].max()
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
