"""``toploc sim kidnap``: put the simulated robot at a random pose in a look-alike room and let
it find out where it is, driving to disambiguate (issue 5, section 3).
"""

from __future__ import annotations

import json
import statistics
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click
from tqdm import tqdm

from localizer.active import ActiveParams, ActiveResult, localize_actively
from localizer.belief import LocalizationState
from localizer.localizer import Localizer, LocalizerConfig
from localizer.policy import POLICIES
from robot.conditions import CONDITIONS
from robot.worlds import make_world
from toploc.maps import ensure_world_map, kidnapped_robot, load_map

# The rooms a kidnapped robot is put in, per world: its look-alike rooms.
KIDNAP_ROOMS = {"building": ("office_a", "office_b")}


@dataclass(frozen=True)
class Trial:
    """One kidnapping: where the robot really was and how localization ended."""

    trial: int
    true_room: str
    result: ActiveResult
    seconds: float

    @property
    def success(self) -> bool:
        """Localized, and in the right room."""
        final = self.result.final
        return final.state is LocalizationState.LOCALIZED and final.top[0] == self.true_room

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


@click.command("kidnap")
@click.option("--world", type=click.Choice(sorted(KIDNAP_ROOMS)), default="building")
@click.option("--trials", type=click.IntRange(min=1), default=20, show_default=True)
@click.option(
    "--policy",
    type=click.Choice(sorted(POLICIES)),
    default="separating",
    show_default=True,
    help="Where to drive when the belief is ambiguous.",
)
@click.option("--seed", type=int, default=0, show_default=True, help="Seeds the kidnappings.")
@click.option(
    "--db",
    "db_path",
    type=click.Path(dir_okay=False, exists=True, path_type=Path),
    default=None,
    help="The world's map (default: rendered and built once into the cache, see README).",
)
@click.option(
    "--condition",
    type=click.Choice(sorted(CONDITIONS)),
    default="default",
    show_default=True,
    help="Capture condition of the kidnapped robot's camera.",
)
@click.option("--motion-noise", type=click.FloatRange(min=0), default=0.05, show_default=True)
@click.option("--max-targets", type=click.IntRange(min=0), default=4, show_default=True)
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path))
def kidnap(
    world: str,
    trials: int,
    policy: str,
    seed: int,
    db_path: Path | None,
    condition: str,
    motion_noise: float,
    max_targets: int,
    json_path: Path | None,
) -> None:
    """Kidnap the simulated robot into a look-alike room, TRIALS times, and localize actively.

    Per trial: true room, final belief, steps (places driven to), distance driven, frames used,
    success (localized in the right room); then the totals.
    """
    db = db_path or ensure_world_map(world)
    localizer = Localizer(load_map(db), LocalizerConfig())
    scene_world = make_world(world)
    params = ActiveParams(max_targets=max_targets)
    rooms = KIDNAP_ROOMS[world]
    done: list[Trial] = []
    for i in tqdm(range(trials), desc=f"kidnap/{policy}", unit="trial"):
        true_room = rooms[i % len(rooms)]
        robot = kidnapped_robot(
            scene_world, true_room, seed * 100_000 + i, db, motion_noise, condition
        )
        start = time.perf_counter()
        result = localize_actively(localizer, robot, policy, params)
        trial = Trial(i, true_room, result, time.perf_counter() - start)
        done.append(trial)
        final = result.final
        tqdm.write(
            f"trial {i:2d}: in {true_room:9s} -> {final.top[0]:9s} p={final.top[1]:.3f} "
            f"{final.state!s:9s} steps {len(result.visits)} {result.distance_m:5.2f} m "
            f"{result.frames:3d} frames {'ok' if trial.success else 'FAILED'}"
        )
    summary = totals(done)
    click.echo(
        f"{policy}: success {summary['success_rate']:.0%} of {trials}, "
        f"first look right {summary['first_look_right']:.0%} "
        f"(ambiguous {summary['first_look_ambiguous']:.0%}), "
        f"mean steps {summary['mean_steps']:.2f}, "
        f"mean distance {summary['mean_distance_m']:.2f} m, "
        f"mean frames {summary['mean_frames']:.1f}, {summary['mean_seconds']:.1f} s per trial"
    )
    if json_path is not None:
        report = {"world": world, "policy": policy, "seed": seed, "condition": condition}
        report |= {"trials": [t.to_json() for t in done], "totals": summary}
        json_path.write_text(json.dumps(report, indent=2) + "\n")
        click.echo(f"wrote {json_path}")
