"""The belief over rooms: a discrete Bayes filter on the room graph, and the localized /
ambiguous / lost test (the likelihood of one frame's evidence is :mod:`localizer.likelihood`).

Pure core: numpy and dataclasses in, numpy and dataclasses out; no I/O.

Evidence is anything with ``.place_id``, ``.room``, ``.inliers`` and ``.spread_inliers`` (see
:class:`PlaceScore`): per stored place, the number of essential-matrix RANSAC inliers between
the query panorama and that place (hundreds for the right place, about 0-20 for unrelated
places), and that number weighted by the share of the query's horizon they cover.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from enum import StrEnum
from typing import Any

import numpy as np
from filterpy.discrete_bayes import normalize as fp_normalize
from filterpy.discrete_bayes import update as fp_update
from scipy.stats import entropy as scipy_entropy

from localizer.evidence import ALL_ROUND_COVERAGE
from localizer.likelihood import PlaceScore, max_inliers, place_count

BELIEF_SCHEMA = 1


# --------------------------------------------------------------------------------------------
# Filter
# --------------------------------------------------------------------------------------------


def transition_matrix(
    rooms: Sequence[str],
    edges: Iterable[tuple[str, str]],
    stay_probability: float,
    anywhere_probability: float = 0.0,
) -> np.ndarray:
    """Row-stochastic matrix ``T[i, j] = P(room j after a move | room i before)``.

    A room keeps ``stay_probability`` and shares the rest equally among its graph neighbours
    (edges are undirected); a room without neighbours keeps everything. With
    ``anywhere_probability`` the robot may also have gone to any room, the graph
    notwithstanding (driven through several rooms, carried, or through a door the map does not
    hold): each row is that share of the uniform distribution and the rest of the graph's.
    """
    if not 0.0 <= stay_probability <= 1.0:
        raise ValueError(f"stay_probability must be in [0, 1], got {stay_probability}")
    if not 0.0 <= anywhere_probability <= 1.0:
        raise ValueError(f"anywhere_probability must be in [0, 1], got {anywhere_probability}")
    index = _room_index(rooms)
    adjacency = np.zeros((len(index), len(index)), dtype=bool)
    for room_a, room_b in edges:
        for name in (room_a, room_b):
            if name not in index:
                raise ValueError(f"edge ({room_a!r}, {room_b!r}) names unknown room {name!r}")
        if room_a != room_b:
            adjacency[index[room_a], index[room_b]] = adjacency[index[room_b], index[room_a]] = True
    degree = adjacency.sum(axis=1)
    transition = np.zeros(adjacency.shape)
    has_exit = degree > 0
    transition[has_exit] = adjacency[has_exit] * ((1.0 - stay_probability) / degree[has_exit, None])
    np.fill_diagonal(transition, np.where(has_exit, stay_probability, 1.0))
    return (1.0 - anywhere_probability) * transition + anywhere_probability / len(index)


def predict_on_graph(belief: np.ndarray, transition: np.ndarray) -> np.ndarray:
    """Prior after a move: ``prior[j] = sum_i belief[i] * T[i, j]`` (total probability)."""
    return np.asarray(belief, dtype=float) @ transition


def entropy_bits(probabilities: np.ndarray) -> float:
    """Shannon entropy of a distribution, in bits."""
    return float(scipy_entropy(np.asarray(probabilities, dtype=float), base=2))


class BeliefFilter:
    """Discrete Bayes filter over the rooms of the room graph; holds the current belief.

    ``predict()`` when the robot has moved (probability flows only along graph edges),
    ``update(likelihood)`` with :func:`room_likelihood` after each capture.

    filterpy's ``discrete_bayes.predict`` shifts and convolves a 1-D array (positions on a
    line or ring); rooms form an arbitrary graph, so the prediction here is the product with the
    graph's transition matrix. The update and normalisation are filterpy's.
    """

    def __init__(
        self,
        rooms: Sequence[str],
        edges: Iterable[tuple[str, str]] = (),
        stay_probability: float = 0.8,
    ) -> None:
        self.rooms: tuple[str, ...] = tuple(_room_index(rooms))
        self.edges: tuple[tuple[str, str], ...] = tuple((a, b) for a, b in edges)
        self.stay_probability = stay_probability
        self.transition = transition_matrix(self.rooms, self.edges, stay_probability)
        self._belief = np.full(len(self.rooms), 1.0 / len(self.rooms))

    @property
    def probabilities(self) -> np.ndarray:
        """The current belief, in the order of :attr:`rooms` (a copy; sums to 1)."""
        return self._belief.copy()

    def as_dict(self) -> dict[str, float]:
        """The current belief as ``{room: probability}``."""
        return {room: float(p) for room, p in zip(self.rooms, self._belief, strict=True)}

    def reset(self, prior: Mapping[str, float] | None = None) -> None:
        """Uniform belief (global localization), or ``prior`` normalised.

        Rooms missing from ``prior`` get 0. Raises ``ValueError`` for an unknown room, a negative
        or non-finite weight, or weights that are all zero.
        """
        if prior is None:
            self._belief = np.full(len(self.rooms), 1.0 / len(self.rooms))
            return
        weights = np.zeros(len(self.rooms))
        index = {room: i for i, room in enumerate(self.rooms)}
        for room, weight in prior.items():
            if room not in index:
                raise ValueError(f"prior names unknown room {room!r}; rooms are {list(self.rooms)}")
            if not (math.isfinite(weight) and weight >= 0):
                raise ValueError(f"prior weight for room {room!r} must be >= 0, got {weight}")
            weights[index[room]] = weight
        if weights.max() <= 0:
            raise ValueError(f"prior weights are all zero: {dict(prior)}")
        self._belief = fp_normalize(weights / weights.max())  # huge weights would sum to inf

    def predict(
        self, stay_probability: float | None = None, anywhere_probability: float = 0.0
    ) -> np.ndarray:
        """Spread the belief along the graph after a move; returns the new belief.

        ``stay_probability`` overrides the filter's value for this move only (e.g. closer to 1
        for a short move inside a room); ``anywhere_probability``: the share of the belief
        that may have gone to any room (see :func:`transition_matrix`).
        """
        transition = (
            self.transition
            if stay_probability is None and anywhere_probability == 0.0
            else transition_matrix(
                self.rooms,
                self.edges,
                self.stay_probability if stay_probability is None else stay_probability,
                anywhere_probability,
            )
        )
        self._belief = fp_normalize(predict_on_graph(self._belief, transition))
        return self.probabilities

    def update(self, likelihood: np.ndarray) -> np.ndarray:
        """Bayes update with a likelihood per room (order of :attr:`rooms`); returns the belief."""
        lik = np.asarray(likelihood, dtype=float)
        if lik.shape != self._belief.shape:
            raise ValueError(
                f"likelihood has shape {lik.shape}, expected ({len(self.rooms)},) for {self.rooms}"
            )
        if not np.all(np.isfinite(lik)) or np.any(lik < 0):
            raise ValueError(f"likelihood must be finite and >= 0, got {lik.tolist()}")
        if float(np.dot(lik, self._belief)) <= 0:
            raise ValueError(f"likelihood {lik.tolist()} is zero wherever the belief is non-zero")
        self._belief = fp_update(lik, self._belief.copy())
        return self.probabilities


# --------------------------------------------------------------------------------------------
# State
# --------------------------------------------------------------------------------------------


class LocalizationState(StrEnum):
    """What the localizer can say. :func:`classify` gives the first three; the service sets
    ``homing`` while it drives to disambiguate."""

    LOCALIZED = "localized"
    AMBIGUOUS = "ambiguous"
    LOST = "lost"
    HOMING = "homing"


@dataclass(frozen=True)
class StateThresholds:
    """Thresholds of :func:`classify`.

    - ``localized_ratio = 10``: the top room is at least 10 times as likely as the second
      (with two rooms: top >= 0.91). About four consistent 10-inlier frames from a 50/50 start,
      or two 30-inlier ones.
    - ``one_place_ratio = 20``: the ratio asked instead when the top room has one place (or
      none) in the map (the localizer applies it, :meth:`Localizer.belief`): such a room is
      judged from one viewpoint, and the calibration saw none of its own counts. With 10 for
      every room, maps of the bare house with one place per room said ``localized`` for 4
      views of another room seen through a door (a hall seen from a bedroom's door), at 11 to
      18 times the second room: 0, 2, 1 and 1 of 50 queries with the house rendered at
      1024 px, rendered at 2048 px and read at 1024 or at 2048, and with other textures
      (``--seed 11``). No wrong answer reached 20 there, and none reached 10 on maps with
      several places per room (the dense house maps, the photo rooms, the building's queries;
      its leave-one-out of twin offices is wrong by construction). docs/results.md.
    - ``min_coverage = 0.6``: and the latest frame's inliers with the top room's places, all
      of them together, cover at least this share of the horizon
      (:data:`localizer.evidence.ALL_ROUND_COVERAGE`), or the frame was taken on one of its
      places; otherwise ``ambiguous`` (the localizer applies it, :meth:`Localizer.belief`).
      A robot in a doorway, or in the next room looking through the door, sees a room on
      half the horizon or less: on recorded maps of ``building`` with one place per room,
      robots just inside an office said ``localized`` in the corridor at 0.97 from the
      corridor's place at 43 and 57 inliers covering 0.51 and 0.35 of the horizon (the
      office's own place, a metre or two away, at 17 and 13).
    - ``max_entropy_bits = 1.0``: and the belief is concentrated (e.g. 0.9 on one room and the
      rest over four others is 0.67 bits; a 50/50 split is 1 bit, which is never localized
      anyway because its ratio is 1).
    - ``lost_min_inliers = 20``: the latest frame's best place has a lower count than this, so
      nothing in the map matched (the localizer sets its likelihood's ``min_inliers`` here, on
      the same count).
    """

    localized_ratio: float = 10.0
    one_place_ratio: float = 20.0
    min_coverage: float = ALL_ROUND_COVERAGE
    max_entropy_bits: float = 1.0
    lost_min_inliers: int = 20

    def __post_init__(self) -> None:
        if not min(self.localized_ratio, self.one_place_ratio) >= 1.0:
            raise ValueError(
                f"localized_ratio and one_place_ratio must be >= 1, got {self.localized_ratio}"
                f" and {self.one_place_ratio}"
            )
        if not 0.0 <= self.min_coverage <= 1.0:
            raise ValueError(f"min_coverage must be in [0, 1], got {self.min_coverage}")
        if not self.max_entropy_bits >= 0.0:
            raise ValueError(f"max_entropy_bits must be >= 0, got {self.max_entropy_bits}")
        if self.lost_min_inliers < 0:
            raise ValueError(f"lost_min_inliers must be >= 0, got {self.lost_min_inliers}")


def top_two_ratio(probabilities: np.ndarray) -> float:
    """Top probability over the second (``inf`` with one room or a zero second)."""
    p = np.sort(np.asarray(probabilities, dtype=float))[::-1]
    if p.size < 2 or p[1] <= 0:
        return math.inf
    return float(p[0] / p[1])


def classify(
    probabilities: np.ndarray,
    thresholds: StateThresholds | None = None,
    evidence_max_inliers: float | None = None,
) -> LocalizationState:
    """Localized, ambiguous or lost.

    Lost: ``evidence_max_inliers`` (the best place's count in the latest frame) is below
    ``lost_min_inliers``; ``None`` (no frame yet) skips this test. Localized: top-two ratio
    >= ``localized_ratio`` and entropy <= ``max_entropy_bits``. Otherwise ambiguous.
    """
    thresholds = thresholds or StateThresholds()
    if evidence_max_inliers is not None and evidence_max_inliers < thresholds.lost_min_inliers:
        return LocalizationState.LOST
    if (
        top_two_ratio(probabilities) >= thresholds.localized_ratio
        and entropy_bits(probabilities) <= thresholds.max_entropy_bits
    ):
        return LocalizationState.LOCALIZED
    return LocalizationState.AMBIGUOUS


@dataclass(frozen=True)
class PartlySeen:
    """Why a belief sure enough by its odds says ``ambiguous``: the latest frame saw its most
    likely ``room`` on ``horizon_share`` of the horizon (0 to 1), less than the
    ``needed_share`` (:attr:`StateThresholds.min_coverage`). The robot may stand at that
    room's door, or in a room the map lacks and see it through the door; homing to one of
    its places and looking there tells."""

    room: str
    horizon_share: float
    needed_share: float

    def to_json(self) -> dict[str, Any]:
        """``{"room", "horizon_share", "needed_share"}``."""
        return {
            "room": self.room,
            "horizon_share": self.horizon_share,
            "needed_share": self.needed_share,
        }

    @classmethod
    def from_json(cls, data: Any) -> PartlySeen:
        """Inverse of :meth:`to_json`; ``ValueError`` naming what is wrong."""
        if not isinstance(data, Mapping):
            raise ValueError(f"partly_seen must be an object, got {data!r}")
        shares = []
        for name in ("horizon_share", "needed_share"):
            share = _json_number(data.get(name), f"partly_seen.{name}")
            if not 0.0 <= share <= 1.0:
                raise ValueError(f"partly_seen.{name} must be in [0, 1], got {share!r}")
            shares.append(share)
        room = data.get("room")
        if not isinstance(room, str):
            raise ValueError(f"partly_seen.room must be a room name, got {room!r}")
        return cls(room, shares[0], shares[1])


@dataclass(frozen=True)
class RoomBelief:
    """A snapshot of the belief, for the bus, the command line and the policies.

    ``best_place_id`` / ``best_place_room`` / ``best_place_inliers``: the best-matching place of
    the latest frame, if the caller knows it. ``stamp_s``: seconds (caller's clock), optional.
    ``partly_seen``: set when the belief is ``ambiguous`` only because its most likely room was
    seen on too little of the horizon (:class:`PartlySeen`).
    :meth:`to_json` / :meth:`from_json` are the one JSON form of a belief (docs/bus.md).
    """

    rooms: tuple[str, ...]
    probabilities: tuple[float, ...]
    state: LocalizationState
    entropy_bits: float
    best_place_id: int | None = None
    best_place_inliers: int | None = None
    stamp_s: float | None = None
    best_place_room: str | None = None
    partly_seen: PartlySeen | None = None

    def __post_init__(self) -> None:
        if len(self.rooms) != len(self.probabilities) or not self.rooms:
            raise ValueError(f"{len(self.rooms)} rooms but {len(self.probabilities)} probabilities")

    @classmethod
    def from_probabilities(
        cls,
        rooms: Sequence[str],
        probabilities: np.ndarray,
        thresholds: StateThresholds | None = None,
        evidence: Sequence[PlaceScore] | None = None,
        stamp_s: float | None = None,
        count: str | None = None,
    ) -> RoomBelief:
        """Snapshot with state and entropy computed; ``evidence`` (latest frame) sets the best
        place and the lost test, on ``count``: the count its likelihood reads (required with
        ``evidence``, see :func:`localizer.likelihood.place_count`)."""
        p = np.asarray(probabilities, dtype=float)
        best, top = None, None
        if evidence is not None:
            if count is None:
                raise ValueError("give the count the likelihood reads with the evidence")
            top = max_inliers(evidence, count=count)
            best = max(evidence, key=lambda e: place_count(e, count), default=None)
        state = classify(p, thresholds, top)
        return cls(
            rooms=tuple(rooms),
            probabilities=tuple(float(x) for x in p),
            state=state,
            entropy_bits=entropy_bits(p),
            best_place_id=None if best is None else int(best.place_id),
            best_place_inliers=None if best is None else int(best.inliers),
            stamp_s=stamp_s,
            best_place_room=None if best is None else str(best.room),
        )

    def with_state(self, state: LocalizationState) -> RoomBelief:
        """The same belief with ``state`` set (the service says ``homing`` while it drives)."""
        return replace(self, state=state)

    def as_dict(self) -> dict[str, float]:
        """``{room: probability}``."""
        return dict(zip(self.rooms, self.probabilities, strict=True))

    def ranked(self) -> list[tuple[str, float]]:
        """``(room, probability)`` from most to least likely (ties by room name)."""
        return sorted(self.as_dict().items(), key=lambda rp: (-rp[1], rp[0]))

    @property
    def top(self) -> tuple[str, float]:
        """The most likely room and its probability."""
        return self.ranked()[0]

    @property
    def second(self) -> tuple[str, float] | None:
        """The second most likely room and its probability (``None`` with one room)."""
        ranked = self.ranked()
        return ranked[1] if len(ranked) > 1 else None

    def to_json(self) -> dict[str, Any]:
        """The belief message: ``{"schema", "kind": "belief", "rooms": {name: p}, "state",
        "entropy_bits", "top", "second", "top_two_ratio", "best_place": {"place_id", "room",
        "inliers"} | null, "stamp"}`` (ratio ``null`` when infinite; ``stamp`` in seconds), and
        ``"partly_seen"`` (:meth:`PartlySeen.to_json`) when it is set."""
        ratio = top_two_ratio(np.asarray(self.probabilities))
        second = self.second
        best_place = None
        if self.best_place_id is not None:
            best_place = {
                "place_id": self.best_place_id,
                "room": self.best_place_room,
                "inliers": self.best_place_inliers,
            }
        message = {
            "schema": BELIEF_SCHEMA,
            "kind": BELIEF_KIND,
            "rooms": self.as_dict(),
            "state": str(self.state),
            "entropy_bits": self.entropy_bits,
            "top": {"room": self.top[0], "probability": self.top[1]},
            "second": None if second is None else {"room": second[0], "probability": second[1]},
            "top_two_ratio": ratio if math.isfinite(ratio) else None,
            "best_place": best_place,
            "stamp": self.stamp_s,
        }
        if self.partly_seen is not None:
            message["partly_seen"] = self.partly_seen.to_json()
        return message

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> RoomBelief:
        """Inverse of :meth:`to_json`, checking every field (``top``, ``second`` and
        ``top_two_ratio`` are derived, so they are recomputed rather than read). Raises
        ``ValueError`` naming the field that is missing or wrong."""
        if not isinstance(data, Mapping):
            raise ValueError(f"a belief must be a JSON object, got {type(data).__name__}")
        if data.get("schema") != BELIEF_SCHEMA:
            raise ValueError(f"belief schema {data.get('schema')!r} is not {BELIEF_SCHEMA}")
        rooms = _json_rooms(_field(data, "rooms"))
        state = _field(data, "state")
        if state not in _STATES:
            raise ValueError(f"state must be one of {_STATES}, got {state!r}")
        entropy = _json_number(_field(data, "entropy_bits"), "entropy_bits")
        best = _field(data, "best_place")
        stamp = data.get("stamp")
        partly_seen = data.get("partly_seen")
        if best is not None and not isinstance(best, Mapping):
            raise ValueError(f"best_place must be an object or null, got {best!r}")
        return cls(
            rooms=tuple(rooms),
            probabilities=tuple(rooms.values()),
            state=LocalizationState(state),
            entropy_bits=entropy,
            best_place_id=None if best is None else _json_int(best, "place_id"),
            best_place_inliers=None if best is None else _json_int(best, "inliers"),
            stamp_s=None if stamp is None else _json_number(stamp, "stamp"),
            best_place_room=None if best is None else _json_room(best.get("room")),
            partly_seen=None if partly_seen is None else PartlySeen.from_json(partly_seen),
        )


BELIEF_KIND = "belief"
_STATES = tuple(str(state) for state in LocalizationState)


def _field(data: Mapping[str, Any], name: str) -> Any:
    if name not in data:
        raise ValueError(f"a belief needs the field {name!r}; got {sorted(data)}")
    return data[name]


def _json_number(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def _json_int(data: Mapping[str, Any], name: str) -> int:
    value = data.get(name)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"best_place.{name} must be an integer, got {value!r}")
    return value


def _json_room(value: Any) -> str | None:
    if value is not None and not isinstance(value, str):
        raise ValueError(f"best_place.room must be a room name or null, got {value!r}")
    return value


def _json_rooms(value: Any) -> dict[str, float]:
    if not isinstance(value, Mapping) or not value:
        raise ValueError(f"rooms must be a non-empty object {{room: p}}, got {value!r}")
    rooms = {}
    for room, p in value.items():
        probability = _json_number(p, f"rooms[{room!r}]")
        if not 0.0 <= probability <= 1.0:
            raise ValueError(f"rooms[{room!r}] must be a probability, got {p!r}")
        rooms[str(room)] = probability
    return rooms


def _room_index(rooms: Sequence[str]) -> dict[str, int]:
    names = list(rooms)
    if not names:
        raise ValueError("rooms must not be empty")
    if len(set(names)) != len(names):
        raise ValueError(f"room names must be unique, got {names}")
    return {room: i for i, room in enumerate(names)}
