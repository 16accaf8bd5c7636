"""``toploc simulate``: the thesis's homing simulation (tables B.1-B.4), thesis and best methods."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import click
from tqdm import tqdm

from homing.experiments import (
    EXPERIMENTS,
    WORLDS,
    Setting,
    run_row,
    run_setting,
    settings,
)
from homing.report import agreement, format_tables, summarise_explanations
from mapdb.workers import spawn_process_pool


def _tasks(
    experiments: list[str], worlds: tuple[int, ...], methods: list[str], runs: int, seed: int
) -> list[tuple[Setting, str, int, int]]:
    return [
        (setting, method, runs, seed)
        for experiment in experiments
        for setting in settings(experiment, worlds)
        for method in methods
    ]


def run_simulation(
    experiments: list[str],
    worlds: tuple[int, ...] = WORLDS,
    methods: tuple[str, ...] = ("thesis", "best"),
    runs: int = 20,
    seed: int = 0,
    jobs: int = 1,
    progress: bool = False,
) -> list[dict[str, Any]]:
    """Every row of the chosen experiments, in table order, on ``jobs`` processes."""
    tasks = _tasks(experiments, worlds, list(methods), runs, seed)
    bar = tqdm(total=len(tasks), desc="simulating", unit="setting", disable=not progress)
    rows: list[dict[str, Any]] = []
    if jobs > 1:
        with spawn_process_pool(jobs) as pool:  # the CLI process has imported OpenCV
            for row in pool.map(run_row, tasks, chunksize=4):
                rows.append(row)
                bar.update()
    else:
        for task in tasks:
            rows.append(run_row(task))
            bar.update()
    bar.close()
    return rows


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
    methods = ("thesis", "best") if method == "both" else (method,)
    rows = run_simulation(experiments, worlds, methods, runs, seed, jobs, progress=True)
    click.echo(format_tables(rows))
    summary = agreement(rows)
    if summary["compared"]:
        click.echo(
            f"\nthesis method vs paper: {summary['within']}/{summary['compared']} rows within"
            " 20 percentage points of the printed success rate"
        )
    if summary["compared"]:
        click.echo(summarise_explanations(rows))
    if explain_path:
        from homing.explanations import explain, format_explanations

        explanations = explain(rows)
        explain_path.write_text(format_explanations(explanations))
        click.echo(f"wrote {len(explanations)} explained rows to {explain_path}")
    if json_path:
        json_path.write_text(json.dumps(rows, indent=1))
        click.echo(f"wrote {len(rows)} rows to {json_path}")
    if plot_path:
        from homing.plots import plot_simulation  # matplotlib only when asked for

        default = {
            s.world: s
            for s in settings(experiments[0], worlds)
            if s.parameter == next(iter(s2.parameter for s2 in settings(experiments[0], worlds)))
        }
        tracks = {}
        for w, setting in default.items():
            base = next(s for s in settings(experiments[0], (w,)))
            for m in methods:
                result = run_setting(base, m, min(runs, 5), seed, keep_tracks=True)  # type: ignore[arg-type]
                tracks[(w, m)] = (base.params, result.tracks or [])
            del setting
        plot_simulation(rows, tracks, plot_path)
        click.echo(f"wrote {plot_path}")
