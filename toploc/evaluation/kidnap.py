"""Kidnapped-robot trials: the simulated robot is put at a seeded random pose in a look-alike room
and localizes actively, driving to disambiguate (issue 5, section 3).

:func:`run_kidnappings` is the loop of ``toploc sim kidnap``; it returns a :class:`KidnapRun`
whose :meth:`KidnapRun.to_json` is the command's ``--json`` report.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from localizer.active import ActiveParams, ActiveResult, localize_actively
from localizer.belief import LocalizationState
from localizer.localizer import Localizer, LocalizerConfig
from robot.worlds import make_world
from toploc.maps import ensure_world_map, kidnapped_robot, load_map

# The rooms a kidnapped robot is put in, per world: its look-alike rooms.
KIDNAP_ROOMS = {"building": ("office_a", "office_b")}


@dataclass(frozen=True)
class Trial:
    """One kidnapping: where the robot really was and how localization ended (wall seconds)."""

    trial: int
    true_room: str
    result: ActiveResult
    seconds: float

    @property
    def success(self) -> bool:
        """Localized, and in the right room."""
        final = self.result.final
        return final.state is LocalizationState.LOCALIZED and final.top[0] == self.true_room

    def describe(self) -> str:
        """One line: true room, final belief, steps, distance (m), frames, ok or FAILED."""
        result, final = self.result, self.result.final
        return (
            f"trial {self.trial:2d}: in {self.true_room:9s} -> {final.top[0]:9s} "
            f"p={final.top[1]:.3f} {final.state!s:9s} steps {len(result.visits)} "
            f"{result.distance_m:5.2f} m {result.frames:3d} frames "
            f"{'ok' if self.success else 'FAILED'}"
        )

    def to_json(self) -> dict[str, Any]:
        final = self.result.final
        return {
            "trial": self.trial,
            "true_room": self.true_room,
            "first_belief": self.result.first.to_json(),
            "final_belief": final.to_json(),
            "final_room": final.top[0],
            "final_state": str(final.state),
            "steps": len(self.result.visits),
            "visited": [v.place_id for v in self.result.visits],
            "homing": [v.homing.reason for v in self.result.visits],
            "distance_m": self.result.distance_m,
            "frames": self.result.frames,
            "success": self.success,
            "seconds": self.seconds,
        }


def totals(trials: list[Trial]) -> dict[str, Any]:
    """Success rate, first-look accuracy and means over the trials."""
    n = len(trials)
    return {
        "trials": n,
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
    }


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
) -> KidnapRun:
    """Kidnap the simulated robot into the look-alike rooms of ``world`` (``KIDNAP_ROOMS``, in
    turn), ``trials`` times, and localize actively with ``policy``.

    ``db_path`` is the world's map (default: rendered and built once into the cache, see
    :func:`toploc.maps.ensure_world_map`); trial ``i`` is seeded with ``seed * 100_000 + i``;
    ``condition`` is the robot camera's capture condition; ``motion_noise`` the fraction of each
    turn and drive; ``max_targets`` the most places driven to. ``on_trial`` is called after each
    trial (for logging; use ``tqdm.write`` to print under the progress bar).
    """
    db = db_path or ensure_world_map(world)
    localizer = Localizer(load_map(db), LocalizerConfig())
    scene_world = make_world(world)
    params = ActiveParams(max_targets=max_targets)
    rooms = KIDNAP_ROOMS[world]
    done: list[Trial] = []
    for i in tqdm(range(trials), desc=f"kidnap/{policy}", unit="trial", disable=not progress):
        true_room = rooms[i % len(rooms)]
        robot = kidnapped_robot(
            scene_world, true_room, seed * 100_000 + i, db, motion_noise, condition
        )
        start = time.perf_counter()
        result = localize_actively(localizer, robot, policy, params)
        trial = Trial(i, true_room, result, time.perf_counter() - start)
        done.append(trial)
        if on_trial is not None:
            on_trial(trial)
    return KidnapRun(world, policy, seed, condition, tuple(done))
