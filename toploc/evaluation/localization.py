"""Single-shot localization measured: the query loops and their honest scoring.

The loops ask a :class:`~localizer.localizer.Localizer` once per query, from a uniform prior:
every panorama of a dataset (:func:`localize_dataset`, typically under another condition than
the map), or every place of the map against the map without it (:func:`localize_leave_one_out`).
Each returns a :class:`LocalizationRun`. The scoring is pure: a list of :class:`QueryOutcome`
and the map's rooms in, a :class:`LocalizationScore` out (:func:`score_localization`).

Every query falls into exactly one of five outcomes (:data:`OUTCOMES`, :func:`outcome_of`):
right and localized, right but ambiguous, wrong and localized (confidently wrong), wrong and
ambiguous, lost. A ``lost`` answer is never right, whatever room its flat belief puts first; a
query from a room the map does not have can only be right by being ``lost``.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from localizer.belief import RoomBelief
from localizer.localizer import Localizer, Observation
from localizer.panorama_io import read_panorama
from mapdb.dataset import read_dataset
from toploc.evaluation.reliability import Reliability, reliability

OUTCOMES = ("right_localized", "right_ambiguous", "wrong_localized", "wrong_ambiguous", "lost")
"""The five outcomes of a query; ``wrong_localized`` (confidently wrong) is the one that must
be 0."""
ONE_SHOT_STATES = ("localized", "ambiguous", "lost")
"""The states a one-shot query can end in (``homing`` only happens while the robot drives)."""
LOST_COLUMN = "(lost)"
"""The confusion matrix's column for lost answers, which name no room."""


@dataclass(frozen=True)
class QueryOutcome:
    """One query: its true room, the belief's top room, the top room's stated probability
    (0..1), the belief's state, and stage times (ms)."""

    image: str
    true_room: str
    predicted_room: str
    top_probability: float
    state: str
    timing_ms: Mapping[str, float]

    def __post_init__(self) -> None:
        if not 0.0 <= self.top_probability <= 1.0:
            raise ValueError(
                f"query {self.image}: top probability must be in 0..1, got {self.top_probability}"
            )

    @property
    def total_ms(self) -> float:
        """Extraction + retrieval + verification, in milliseconds."""
        return float(sum(self.timing_ms.values()))


def outcome_of(query: QueryOutcome, map_rooms: Collection[str]) -> str:
    """Which of :data:`OUTCOMES` ``query`` is. Right means the state is not ``lost`` and the top
    room is the true room, which must be in ``map_rooms``; ``ValueError`` for a state other
    than localized, ambiguous or lost, naming it."""
    if query.state not in ONE_SHOT_STATES:
        raise ValueError(
            f"query {query.image}: state {query.state!r} cannot end a one-shot query "
            f"(expected one of {', '.join(ONE_SHOT_STATES)})"
        )
    if query.state == "lost":
        return "lost"
    right = query.true_room in map_rooms and query.predicted_room == query.true_room
    return f"{'right' if right else 'wrong'}_{query.state}"


def is_right(outcome: str) -> bool:
    """Whether an outcome of :data:`OUTCOMES` names the true room (``lost`` never does)."""
    return outcome.startswith("right_")


def count_outcomes(outcomes: Iterable[str]) -> dict[str, int]:
    """How many of each of :data:`OUTCOMES` (every one present, 0 if none)."""
    counts = dict.fromkeys(OUTCOMES, 0)
    for outcome in outcomes:
        counts[outcome] += 1
    return counts


def outcome_rates(counts: Mapping[str, int]) -> dict[str, float]:
    """Each count as a share of their sum (0..1); ``ValueError`` if the sum is 0."""
    n = sum(counts.values())
    if n == 0:
        raise ValueError("no outcomes to take rates of")
    return {outcome: count / n for outcome, count in counts.items()}


@dataclass(frozen=True)
class RoomOutcomes:
    """The outcomes of the queries from one true room; ``in_map``: the map has that room."""

    in_map: bool
    counts: dict[str, int]

    def to_json(self) -> dict[str, Any]:
        return {"in_map": self.in_map, "counts": self.counts, "rates": outcome_rates(self.counts)}


@dataclass(frozen=True)
class UnknownRooms:
    """Queries from rooms the map does not have, by state: right only when ``lost``;
    ``localized`` ones are confidently wrong."""

    rooms: tuple[str, ...]
    n: int
    lost: int
    ambiguous: int
    localized: int

    def to_json(self) -> dict[str, Any]:
        return {
            "n": self.n,
            "lost": self.lost,
            "ambiguous": self.ambiguous,
            "localized": self.localized,
            "rooms": list(self.rooms),
        }


@dataclass(frozen=True)
class KnownRooms:
    """The queries from rooms the map holds, which the headline scores (a query from a room
    the map lacks can only be right by being lost: :class:`UnknownRooms` reports them apart).
    ``outcomes``: counts of :data:`OUTCOMES`; ``top1``: share right (lost is not);
    ``top1_answered``: the same among those not lost; ``answer_rate``: share not lost;
    ``ambiguous_rate``: share ambiguous. Rates in 0..1, None when there is no such query (or
    for ``top1_answered``, none answered)."""

    n: int
    outcomes: dict[str, int]
    top1: float | None
    top1_answered: float | None
    answer_rate: float | None
    ambiguous_rate: float | None

    @classmethod
    def of(cls, outcomes: Sequence[str]) -> KnownRooms:
        """From the :data:`OUTCOMES` of the queries from rooms of the map."""
        counts = count_outcomes(outcomes)
        n = len(outcomes)
        answered = n - counts["lost"]
        right = counts["right_localized"] + counts["right_ambiguous"]
        ambiguous = counts["right_ambiguous"] + counts["wrong_ambiguous"]
        return cls(
            n=n,
            outcomes=counts,
            top1=right / n if n else None,
            top1_answered=right / answered if answered else None,
            answer_rate=answered / n if n else None,
            ambiguous_rate=ambiguous / n if n else None,
        )

    @property
    def rates(self) -> dict[str, float] | None:
        """Each of :data:`OUTCOMES` as a share of these queries (None if there are none)."""
        return outcome_rates(self.outcomes) if self.n else None

    def to_json(self) -> dict[str, Any]:
        return {
            "n": self.n,
            "outcomes": self.outcomes,
            "rates": self.rates,
            "top1": self.top1,
            "top1_answered": self.top1_answered,
            "answer_rate": self.answer_rate,
            "ambiguous_rate": self.ambiguous_rate,
        }


@dataclass(frozen=True)
class LocalizationScore:
    """What ``toploc eval localize`` reports (rates in 0..1, times in milliseconds).

    ``known_room``: the queries from rooms the map holds, scored alone (:class:`KnownRooms`:
    what the report's headline says); ``unknown_room``: the others (:class:`UnknownRooms`).
    The other fields count every query: ``top1``: share of all queries that name the true room
    and are not lost (a query from a room the map lacks never does). ``top1_answered``: the
    same among the queries not lost (``None`` if all are lost); ``answer_rate``: share not
    lost. ``outcomes``/``rates``: counts
    and shares of :data:`OUTCOMES`. ``per_room``: per true room, ``{"n", "top1",
    "ambiguous_rate"}``; ``per_room_outcomes``: per true room, its :class:`RoomOutcomes`.
    ``confusion``: true room -> predicted room (or :data:`LOST_COLUMN`) -> count;
    ``stage_ms_median``: per stage (extraction, retrieval, verification). ``calibration``: the
    top room's stated probability against whether the answer was right (every query, lost
    ones included and never right).
    """

    n: int
    top1: float
    ambiguous_rate: float
    per_room: dict[str, dict[str, float]]
    confusion: dict[str, dict[str, int]]
    ms_median: float
    ms_p95: float
    stage_ms_median: dict[str, float]
    outcomes: dict[str, int]
    top1_answered: float | None
    answer_rate: float
    per_room_outcomes: dict[str, RoomOutcomes]
    unknown_room: UnknownRooms
    calibration: Reliability
    known_room: KnownRooms

    @property
    def rates(self) -> dict[str, float]:
        """Each of :data:`OUTCOMES` as a share of all queries."""
        return outcome_rates(self.outcomes)

    def to_json(self) -> dict[str, Any]:
        return {
            "n": self.n,
            "top1": self.top1,
            "ambiguous_rate": self.ambiguous_rate,
            "per_room": self.per_room,
            "confusion": self.confusion,
            "ms_median": self.ms_median,
            "ms_p95": self.ms_p95,
            "stage_ms_median": self.stage_ms_median,
            "outcomes": self.outcomes,
            "rates": self.rates,
            "top1_answered": self.top1_answered,
            "answer_rate": self.answer_rate,
            "per_room_outcomes": {r: o.to_json() for r, o in self.per_room_outcomes.items()},
            "unknown_room": self.unknown_room.to_json(),
            "calibration": self.calibration.to_json(),
            "known_room": self.known_room.to_json(),
        }


def score_localization(
    queries: Sequence[QueryOutcome], map_rooms: Collection[str]
) -> LocalizationScore:
    """Aggregate query outcomes against the map's rooms; ``ValueError`` if there are none or
    one has a state a one-shot query cannot end in."""
    if not queries:
        raise ValueError("no queries to score")
    outcomes = [outcome_of(q, map_rooms) for q in queries]
    counts = count_outcomes(outcomes)
    answered = len(queries) - counts["lost"]
    per_room, per_room_outcomes = _per_room(queries, outcomes, map_rooms)
    totals = np.array([q.total_ms for q in queries])
    stages = sorted({stage for q in queries for stage in q.timing_ms})
    return LocalizationScore(
        n=len(queries),
        top1=_share(is_right(o) for o in outcomes),
        ambiguous_rate=_share(q.state == "ambiguous" for q in queries),
        per_room=per_room,
        confusion=confusion_matrix(queries),
        ms_median=float(np.median(totals)),
        ms_p95=float(np.percentile(totals, 95)),
        stage_ms_median={
            s: float(np.median([q.timing_ms.get(s, 0.0) for q in queries])) for s in stages
        },
        outcomes=counts,
        top1_answered=(counts["right_localized"] + counts["right_ambiguous"]) / answered
        if answered
        else None,
        answer_rate=answered / len(queries),
        per_room_outcomes=per_room_outcomes,
        unknown_room=unknown_rooms(queries, map_rooms),
        calibration=reliability(
            [q.top_probability for q in queries], [is_right(o) for o in outcomes]
        ),
        known_room=KnownRooms.of(
            [o for q, o in zip(queries, outcomes, strict=True) if q.true_room in map_rooms]
        ),
    )


def _per_room(
    queries: Sequence[QueryOutcome], outcomes: Sequence[str], map_rooms: Collection[str]
) -> tuple[dict[str, dict[str, float]], dict[str, RoomOutcomes]]:
    """Per true room: ``{"n", "top1", "ambiguous_rate"}`` and its :class:`RoomOutcomes`."""
    per_room, per_room_outcomes = {}, {}
    for room in sorted({q.true_room for q in queries}):
        mine = [(q, o) for q, o in zip(queries, outcomes, strict=True) if q.true_room == room]
        per_room[room] = {
            "n": len(mine),
            "top1": _share(is_right(o) for _, o in mine),
            "ambiguous_rate": _share(q.state == "ambiguous" for q, _ in mine),
        }
        per_room_outcomes[room] = RoomOutcomes(
            room in map_rooms, count_outcomes(o for _, o in mine)
        )
    return per_room, per_room_outcomes


def confusion_matrix(queries: Sequence[QueryOutcome]) -> dict[str, dict[str, int]]:
    """True room -> predicted room -> count, every row with every column; a lost answer names
    no room and goes to :data:`LOST_COLUMN` (last, present only if some query is lost)."""
    lost = [q.state == "lost" for q in queries]
    columns = sorted({q.true_room for q in queries} | {q.predicted_room for q in queries})
    columns += [LOST_COLUMN] if any(lost) else []
    confusion = {t: dict.fromkeys(columns, 0) for t in sorted({q.true_room for q in queries})}
    for q, is_lost in zip(queries, lost, strict=True):
        confusion[q.true_room][LOST_COLUMN if is_lost else q.predicted_room] += 1
    return confusion


def unknown_rooms(queries: Sequence[QueryOutcome], map_rooms: Collection[str]) -> UnknownRooms:
    """The queries whose true room is not in ``map_rooms``, counted by state."""
    mine = [q for q in queries if q.true_room not in map_rooms]
    return UnknownRooms(
        rooms=tuple(sorted({q.true_room for q in mine})),
        n=len(mine),
        lost=sum(q.state == "lost" for q in mine),
        ambiguous=sum(q.state == "ambiguous" for q in mine),
        localized=sum(q.state == "localized" for q in mine),
    )


@dataclass(frozen=True)
class LocalizationRun:
    """Every query's outcome, in order, and their score."""

    outcomes: tuple[QueryOutcome, ...]
    score: LocalizationScore


def localize_dataset(
    localizer: Localizer, dataset_dir: Path | str, progress: bool = False
) -> LocalizationRun:
    """Localize every panorama of ``dataset_dir`` once: a folder with ``manifest.csv``, or one
    sub-folder of panoramas per room (:func:`mapdb.dataset.read_dataset`).

    The true room of a query is its manifest row's (its sub-folder's). A bad manifest raises
    :class:`mapdb.errors.ManifestError`, an unreadable image
    :class:`localizer.panorama_io.PanoramaError`, both naming the file.
    """
    outcomes = []
    entries = read_dataset(dataset_dir)
    for entry in tqdm(entries, desc="localize", unit="pano", disable=not progress):
        belief, observation = localizer.localize_once(read_panorama(entry.path))
        outcomes.append(query_outcome(entry.image, entry.room, belief, observation))
    return LocalizationRun(tuple(outcomes), score_localization(outcomes, localizer.map.rooms))


def localize_leave_one_out(localizer: Localizer, progress: bool = False) -> LocalizationRun:
    """Localize each place of the map with its stored fingerprint, the place itself left out.

    The query is named ``"place <id>"``; its true room is the place's room.
    """
    outcomes = []
    for place in tqdm(localizer.map.places, desc="leave-one-out", disable=not progress):
        localizer.reset()
        fingerprint = localizer.map.fingerprint(place.id)
        observation = localizer.observe_fingerprint(fingerprint, exclude=place.id)
        belief = localizer.update(observation)
        outcomes.append(query_outcome(f"place {place.id}", place.room, belief, observation))
    return LocalizationRun(tuple(outcomes), score_localization(outcomes, localizer.map.rooms))


def query_outcome(
    image: str, true_room: str, belief: RoomBelief, observation: Observation
) -> QueryOutcome:
    """The outcome of one query from its belief (top room, its probability, state) and timing."""
    room, probability = belief.top
    return QueryOutcome(
        image, true_room, room, float(probability), str(belief.state), observation.timing_ms
    )


def _share(flags: Any) -> float:
    values = list(flags)
    return sum(values) / len(values)


def format_confusion(confusion: Mapping[str, Mapping[str, int]], max_width: int = 120) -> str:
    """The confusion matrix as a text table (rows: true room, columns: predicted); when that
    would be wider than ``max_width`` characters (many rooms, long names), one line per true
    room listing only the rooms it was taken for."""
    columns = list(dict.fromkeys(p for row in confusion.values() for p in row))
    width = max(len(c) for c in [*columns, *confusion, "true \\ predicted"]) + 1
    if width * (len(columns) + 1) > max_width:
        lines = ["true room: predicted room (count), ..."]
        for true_room, row in confusion.items():
            taken = [f"{room} ({n})" for room, n in sorted(row.items(), key=lambda r: -r[1]) if n]
            lines.append(f"  {true_room}: {', '.join(taken) or '-'}")
        return "\n".join(lines)
    lines = ["true \\ predicted".ljust(width) + "".join(c.rjust(width) for c in columns)]
    for true_room, row in confusion.items():
        cells = "".join(str(row.get(c, 0)).rjust(width) for c in columns)
        lines.append(true_room.ljust(width) + cells)
    return "\n".join(lines)
