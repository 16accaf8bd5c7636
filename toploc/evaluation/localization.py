"""Single-shot localization measured: the query loops and their scoring (top-1 room accuracy,
confusion, ambiguity and timing).

The loops ask a :class:`~localizer.localizer.Localizer` once per query, from a uniform prior:
every panorama of a dataset (:func:`localize_dataset`, typically under another condition than
the map), or every place of the map against the map without it (:func:`localize_leave_one_out`).
Each returns a :class:`LocalizationRun`. The scoring is pure: a list of :class:`QueryOutcome`
in, a :class:`LocalizationScore` out (:func:`score_localization`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from localizer.localizer import Localizer
from localizer.panorama_io import read_panorama
from mapdb.dataset import read_manifest


@dataclass(frozen=True)
class QueryOutcome:
    """One query: its true room, the belief's top room and state, and stage times (ms)."""

    image: str
    true_room: str
    predicted_room: str
    state: str
    timing_ms: Mapping[str, float]

    @property
    def total_ms(self) -> float:
        """Extraction + retrieval + verification, in milliseconds."""
        return float(sum(self.timing_ms.values()))


@dataclass(frozen=True)
class LocalizationScore:
    """What ``toploc eval localize`` reports (rates in 0..1, times in milliseconds).

    ``per_room``: per true room, ``{"n", "top1", "ambiguous_rate"}``; ``confusion``: true room
    -> predicted room -> count; ``stage_ms_median``: per stage (extraction, retrieval,
    verification).
    """

    n: int
    top1: float
    ambiguous_rate: float
    per_room: dict[str, dict[str, float]]
    confusion: dict[str, dict[str, int]]
    ms_median: float
    ms_p95: float
    stage_ms_median: dict[str, float]

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
        }


def score_localization(outcomes: Sequence[QueryOutcome]) -> LocalizationScore:
    """Aggregate query outcomes; ``ValueError`` if there are none."""
    if not outcomes:
        raise ValueError("no queries to score")
    rooms = sorted({o.true_room for o in outcomes} | {o.predicted_room for o in outcomes})
    confusion = {t: dict.fromkeys(rooms, 0) for t in sorted({o.true_room for o in outcomes})}
    for o in outcomes:
        confusion[o.true_room][o.predicted_room] += 1
    per_room = {}
    for room in confusion:
        mine = [o for o in outcomes if o.true_room == room]
        per_room[room] = {
            "n": len(mine),
            "top1": _share(o.predicted_room == room for o in mine),
            "ambiguous_rate": _share(o.state == "ambiguous" for o in mine),
        }
    totals = np.array([o.total_ms for o in outcomes])
    stages = sorted({stage for o in outcomes for stage in o.timing_ms})
    return LocalizationScore(
        n=len(outcomes),
        top1=_share(o.predicted_room == o.true_room for o in outcomes),
        ambiguous_rate=_share(o.state == "ambiguous" for o in outcomes),
        per_room=per_room,
        confusion=confusion,
        ms_median=float(np.median(totals)),
        ms_p95=float(np.percentile(totals, 95)),
        stage_ms_median={
            s: float(np.median([o.timing_ms.get(s, 0.0) for o in outcomes])) for s in stages
        },
    )


@dataclass(frozen=True)
class LocalizationRun:
    """Every query's outcome, in order, and their score."""

    outcomes: tuple[QueryOutcome, ...]
    score: LocalizationScore


def localize_dataset(
    localizer: Localizer, dataset_dir: Path | str, progress: bool = False
) -> LocalizationRun:
    """Localize every panorama of ``dataset_dir`` (a folder with ``manifest.csv``) once.

    The true room of a query is its manifest row's. A bad manifest raises
    :class:`mapdb.errors.ManifestError`, an unreadable image
    :class:`localizer.panorama_io.PanoramaError`, both naming the file.
    """
    outcomes = []
    entries = read_manifest(dataset_dir)
    for entry in tqdm(entries, desc="localize", unit="pano", disable=not progress):
        belief, observation = localizer.localize_once(read_panorama(entry.path))
        outcomes.append(
            QueryOutcome(
                entry.image, entry.room, belief.top[0], str(belief.state), observation.timing_ms
            )
        )
    return LocalizationRun(tuple(outcomes), score_localization(outcomes))


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
        outcomes.append(
            QueryOutcome(
                f"place {place.id}",
                place.room,
                belief.top[0],
                str(belief.state),
                observation.timing_ms,
            )
        )
    return LocalizationRun(tuple(outcomes), score_localization(outcomes))


def _share(flags: Any) -> float:
    values = list(flags)
    return sum(values) / len(values)


def format_confusion(confusion: Mapping[str, Mapping[str, int]]) -> str:
    """The confusion matrix as a text table (rows: true room, columns: predicted)."""
    columns = sorted({p for row in confusion.values() for p in row})
    width = max(len(c) for c in [*columns, *confusion, "true \\ predicted"]) + 1
    lines = ["true \\ predicted".ljust(width) + "".join(c.rjust(width) for c in columns)]
    for true_room, row in confusion.items():
        cells = "".join(str(row.get(c, 0)).rjust(width) for c in columns)
        lines.append(true_room.ljust(width) + cells)
    return "\n".join(lines)
