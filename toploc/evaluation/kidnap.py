"""Kidnapped-robot trials: the simulated robot is put at a seeded random pose in a look-alike room
and localizes actively, driving to disambiguate (issue 5, section 3).

:func:`run_kidnappings` is the loop of ``toploc sim kidnap``; it returns a :class:`KidnapRun`
whose :meth:`KidnapRun.to_json` is the command's ``--json`` report.
"""

from __future__ import annotations

import statistics
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from localizer.active import ActiveParams, ActiveResult, localize_actively
from localizer.belief import LocalizationState
from localizer.localizer import Localizer, LocalizerConfig
from robot.worlds import make_world
from toploc.evaluation.localization import count_outcomes
from toploc.evaluation.reliability import reliability
from toploc.maps import ensure_world_map, kidnapped_robot, load_map

# The rooms a kidnapped robot is put in, per world: its look-alike rooms.
KIDNAP_ROOMS = {
    "building": ("office_a", "office_b"),
    "house": ("bedroom_a", "bedroom_b", "bathroom_a", "bathroom_b"),
}


@dataclass(frozen=True)
class Trial:
    """One kidnapping: the room the robot was put in, how localization ended (wall seconds),
    and the room the robot really was in at the end (``end_room``; a drive may leave the room it
    was put in, and the final belief is judged against where the robot is then; ``None``: the
    room it was put in)."""

    trial: int
    true_room: str
    result: ActiveResult
    seconds: float
    end_room: str | None = None

    @property
    def final_true_room(self) -> str:
        """The room the robot was in when the final belief was formed."""
        return self.end_room or self.true_room

    @property
    def success(self) -> bool:
        """Localized, and in the right room."""
        return self.outcome == "right_localized"

    @property
    def outcome(self) -> str:
        """Which of the five outcomes (:data:`toploc.evaluation.localization.OUTCOMES`) the
        final belief is."""
        final = self.result.final
        if final.state is LocalizationState.LOST:
            return "lost"
        right = "right" if final.top[0] == self.final_true_room else "wrong"
        return f"{right}_{final.state}"

    def describe(self) -> str:
        """One line: true room, final belief, steps, distance (m), frames, ok or FAILED."""
        result, final = self.result, self.result.final
        moved = "" if self.final_true_room == self.true_room else f" (ended in {self.end_room})"
        return (
            f"trial {self.trial:2d}: in {self.true_room:9s}{moved} -> {final.top[0]:9s} "
            f"p={final.top[1]:.3f} {final.state!s:9s} steps {len(result.visits)} "
            f"{result.distance_m:5.2f} m {result.frames:3d} frames "
            f"{'ok' if self.success else 'FAILED'}"
        )

    def to_json(self) -> dict[str, Any]:
        final = self.result.final
        return {
            "trial": self.trial,
            "true_room": self.true_room,
            "end_room": self.final_true_room,
            "first_belief": self.result.first.to_json(),
            "final_belief": final.to_json(),
            "final_room": final.top[0],
            "final_state": str(final.state),
            "steps": len(self.result.visits),
            "visited": [v.place_id for v in self.result.visits],
            "homing": [v.homing.reason for v in self.result.visits],
            "told": [v.told for v in self.result.visits],
            "distance_m": self.result.distance_m,
            "frames": self.result.frames,
            "looks_elsewhere": self.result.looks_elsewhere,
            "ended": self.result.ended,
            "route_checks": [
                {
                    "room": c.room,
                    "start": c.start,
                    "end": c.end,
                    "confirmed": c.confirmed,
                    "end_inliers": c.end_inliers,
                    "end_homing_m": c.end_homing_m,
                    "back_room": c.back_room,
                    "started": c.started,
                    "afresh": c.afresh,
                    "via": c.via,
                }
                for c in self.result.checks
            ],
            "success": self.success,
            "outcome": self.outcome,
            "seconds": self.seconds,
        }


def totals(trials: list[Trial]) -> dict[str, Any]:
    """Success rate, the five outcomes, first-look accuracy, means over the trials, why the
    localizations ended (``endings``: count per :data:`localizer.active.ENDINGS` key met), how
    the route checks came out (``route_checks``), how many robots ended in another room than
    the one they were put in (``ended_elsewhere``), how many ended right and localized in the
    room they were put in (``right_where_put``: they answered the question the kidnapping
    asked; a robot that wandered into the corridor and named it did not), and the
    reliability of the final answers' stated probabilities."""
    n = len(trials)
    finals = [t.result.final for t in trials]
    stated = [final.top[1] for final in finals]
    right = [final.top[0] == t.final_true_room for final, t in zip(finals, trials, strict=True)]
    return {
        "trials": n,
        "outcomes": count_outcomes(t.outcome for t in trials),
        "success_rate": sum(t.success for t in trials) / n,
        "first_look_right": sum(t.result.first.top[0] == t.true_room for t in trials) / n,
        "first_look_ambiguous": sum(
            t.result.first.state is LocalizationState.AMBIGUOUS for t in trials
        )
        / n,
        "mean_steps": statistics.fmean(len(t.result.visits) for t in trials),
        "mean_distance_m": statistics.fmean(t.result.distance_m for t in trials),
        "mean_frames": statistics.fmean(t.result.frames for t in trials),
        "mean_seconds": statistics.fmean(t.seconds for t in trials),
        "drove": sum(bool(t.result.visits) for t in trials),
        "endings": dict(sorted(Counter(t.result.ended for t in trials).items())),
        "route_checks": _route_checks(trials),
        "ended_elsewhere": sum(t.final_true_room != t.true_room for t in trials),
        "right_where_put": sum(t.success and t.final_true_room == t.true_room for t in trials),
        "reliability": reliability(stated, right).to_json(),
    }


def _route_checks(trials: list[Trial]) -> dict[str, int]:
    """How the rooms checked by a recorded route came out: confirmed or not, for the room the
    robot was put in (``own``) and for the others."""
    counts = dict.fromkeys(("own_confirmed", "own_refuted", "other_confirmed", "other_refuted"), 0)
    for trial in trials:
        for check in trial.result.checks:
            whose = "own" if check.room == trial.true_room else "other"
            counts[f"{whose}_{'confirmed' if check.confirmed else 'refuted'}"] += 1
    return counts


def describe_endings(endings: dict[str, int]) -> str:
    """``settled 12, no-telling-place 8``: :func:`totals`' ``endings`` in one phrase."""
    return ", ".join(f"{ending} {n}" for ending, n in endings.items()) or "none"


@dataclass(frozen=True)
class KidnapRun:
    """The settings of a series of kidnappings, and every trial in order."""

    world: str
    policy: str
    seed: int
    condition: str
    trials: tuple[Trial, ...]

    def totals(self) -> dict[str, Any]:
        """:func:`totals` over the trials."""
        return totals(list(self.trials))

    def to_json(self) -> dict[str, Any]:
        """The report: the settings, every trial's :meth:`Trial.to_json` and the totals."""
        report = {
            "world": self.world,
            "policy": self.policy,
            "seed": self.seed,
            "condition": self.condition,
        }
        return report | {"trials": [t.to_json() for t in self.trials], "totals": self.totals()}


def run_kidnappings(
    world: str,
    trials: int,
    policy: str = "separating",
    seed: int = 0,
    db_path: Path | None = None,
    condition: str = "default",
    motion_noise: float = 0.05,
    max_targets: int = 4,
    progress: bool = True,
    on_trial: Callable[[Trial], None] | None = None,
    world_seed: int = 0,
    rooms: tuple[str, ...] | None = None,
) -> KidnapRun:
    """Kidnap the simulated robot into the look-alike rooms of ``world`` (``KIDNAP_ROOMS``, in
    turn), ``trials`` times, and localize actively with ``policy``.

    ``db_path`` is the world's map (default: rendered and built once into the cache, see
    :func:`toploc.maps.ensure_world_map`); trial ``i`` is seeded with ``seed * 100_000 + i``;
    ``condition`` is the robot camera's capture condition; ``motion_noise`` the fraction of each
    turn and drive; ``max_targets`` the most places driven to. ``on_trial`` is called after each
    trial (for logging; use ``tqdm.write`` to print under the progress bar). ``world_seed``
    builds the world (the seed its map was made in); ``rooms`` replaces ``KIDNAP_ROOMS``.
    """
    db = db_path or ensure_world_map(world, seed=world_seed)
    localizer = Localizer(load_map(db), LocalizerConfig())
    scene_world = make_world(world, world_seed)
    params = ActiveParams(max_targets=max_targets)
    rooms = rooms or KIDNAP_ROOMS[world]
    done: list[Trial] = []
    for i in tqdm(range(trials), desc=f"kidnap/{policy}", unit="trial", disable=not progress):
        true_room = rooms[i % len(rooms)]
        robot = kidnapped_robot(
            scene_world, true_room, seed * 100_000 + i, db, motion_noise, condition
        )
        start = time.perf_counter()
        result = localize_actively(localizer, robot, policy, params)
        trial = Trial(i, true_room, result, time.perf_counter() - start, robot.true_room())
        done.append(trial)
        if on_trial is not None:
            on_trial(trial)
    return KidnapRun(world, policy, seed, condition, tuple(done))
