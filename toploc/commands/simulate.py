"""``toploc simulate``: the thesis's homing simulation (tables B.1-B.4), thesis and best methods."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import cast

import click

from homing.thesis.experiments import EXPERIMENTS, WORLDS, Method
from homing.thesis.report import format_tables, summarise_explanations
from toploc.evaluation.simulation import run_simulation, simulation_tracks


@click.command()
@click.option(
    "--experiment",
    type=click.Choice([*EXPERIMENTS, "all"], case_sensitive=False),
    default="B1",
    show_default=True,
    help="Which table of appendix B to reproduce.",
)
@click.option("--world", type=click.IntRange(1, 4), help="Only this world (default: all four).")
@click.option(
    "--runs", type=click.IntRange(1), default=20, show_default=True, help="Runs per setting."
)
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of every random draw.")
@click.option(
    "--method",
    type=click.Choice(["thesis", "best", "both"]),
    default="both",
    show_default=True,
    help="thesis: appendix A exactly; best: toploc's controller; both side by side.",
)
@click.option(
    "--json",
    "json_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the result rows as a JSON list.",
)
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write trajectories and success curves (PNG).",
)
@click.option(
    "--explain",
    "explain_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write a markdown table: every thesis-method row that differs from the paper, and why.",
)
@click.option(
    "--jobs",
    type=click.IntRange(1),
    default=os.cpu_count() or 1,
    show_default=True,
    help="Worker processes.",
)
def simulate(
    experiment: str,
    world: int | None,
    runs: int,
    seed: int,
    method: str,
    json_path: Path | None,
    plot_path: Path | None,
    explain_path: Path | None,
    jobs: int,
) -> None:
    """Reproduce the thesis's ALV homing simulation (chapter 4, tables B.1-B.4).

    Prints each table with the thesis's printed figures ("paper") beside ours.
    """
    experiments = list(EXPERIMENTS) if experiment.lower() == "all" else [experiment.upper()]
    worlds = (world,) if world else WORLDS
    methods = cast(tuple[Method, ...], ("thesis", "best") if method == "both" else (method,))
    run = run_simulation(experiments, worlds, methods, runs, seed, jobs, progress=True)
    rows = run.rows
    click.echo(format_tables(rows))
    summary = run.agreement()
    if summary["compared"]:
        click.echo(
            f"\nthesis method vs paper: {summary['within']}/{summary['compared']} rows within"
            " 20 percentage points of the printed success rate"
        )
    if summary["compared"]:
        click.echo(summarise_explanations(rows))
    if explain_path:
        from homing.thesis.explanations import explain, format_explanations

        explanations = explain(rows)
        explain_path.write_text(format_explanations(explanations))
        click.echo(f"wrote {len(explanations)} explained rows to {explain_path}")
    if json_path:
        json_path.write_text(json.dumps(rows, indent=1))
        click.echo(f"wrote {len(rows)} rows to {json_path}")
    if plot_path:
        from homing.thesis.plots import plot_simulation  # matplotlib only when asked for

        plot_simulation(rows, simulation_tracks(run), plot_path)
        click.echo(f"wrote {plot_path}")
