"""``toploc sim kidnap``: put the simulated robot at a random pose in a look-alike room and let
it find out where it is, driving to disambiguate (issue 5, section 3).
"""

from __future__ import annotations

import json
from pathlib import Path

import click
from tqdm import tqdm

from robot.conditions import CONDITIONS
from toploc.commands.options import db_option, policy_option
from toploc.evaluation.kidnap import KIDNAP_ROOMS, Trial, describe_endings, run_kidnappings


def _print_trial(trial: Trial) -> None:
    tqdm.write(trial.describe())


@click.command("kidnap")
@click.option(
    "--world",
    type=click.Choice(sorted(KIDNAP_ROOMS)),
    default="building",
    show_default=True,
    help="The rendered world, with its look-alike rooms to be kidnapped into.",
)
@click.option(
    "--trials",
    type=click.IntRange(min=1),
    default=20,
    show_default=True,
    help="How many kidnappings (each a seeded random pose in a look-alike room).",
)
@policy_option
@click.option("--seed", type=int, default=0, show_default=True, help="Seeds the kidnappings.")
@db_option(
    "The world's map (default: toploc's built-in map of --world, rendered and built once "
    "into the cache).",
    required=False,
    exists=True,
)
@click.option(
    "--condition",
    type=click.Choice(sorted(CONDITIONS)),
    default="default",
    show_default=True,
    help="Capture condition of the kidnapped robot's camera.",
)
@click.option(
    "--motion-noise",
    type=click.FloatRange(min=0),
    default=0.05,
    show_default=True,
    help="The robot's motion noise: standard deviation as a fraction of each turn and drive.",
)
@click.option(
    "--max-targets",
    type=click.IntRange(min=0),
    default=4,
    show_default=True,
    help="The most places a trial drives to before it gives up.",
)
@click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also write every trial and the totals to this JSON file.",
)
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
    run = run_kidnappings(
        world,
        trials,
        policy=policy,
        seed=seed,
        db_path=db_path,
        condition=condition,
        motion_noise=motion_noise,
        max_targets=max_targets,
        on_trial=_print_trial,
    )
    summary = run.totals()
    click.echo(
        f"{policy}: success {summary['success_rate']:.0%} of {trials}, "
        f"first look right {summary['first_look_right']:.0%} "
        f"(ambiguous {summary['first_look_ambiguous']:.0%}), "
        f"mean steps {summary['mean_steps']:.2f}, "
        f"mean distance {summary['mean_distance_m']:.2f} m, "
        f"mean frames {summary['mean_frames']:.1f}, {summary['mean_seconds']:.1f} s per trial"
    )
    click.echo(f"ended: {describe_endings(summary['endings'])}")
    if json_path is not None:
        json_path.write_text(json.dumps(run.to_json(), indent=2) + "\n")
        click.echo(f"wrote {json_path}")
