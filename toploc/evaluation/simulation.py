"""The thesis's homing simulation (chapter 4, tables B.1-B.4) run over experiments and methods.

The loops of ``toploc simulate``: every setting of the chosen experiments and worlds, once per
method, ``runs`` runs each, on a spawned process pool (:mod:`mapdb.workers`); and, for the plot,
the trajectories of each world's first setting. The experiments themselves (settings, seeds,
summary rows) are :mod:`homing.thesis.experiments`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from tqdm import tqdm

from homing.thesis.experiments import WORLDS, Method, Setting, run_row, run_setting, settings
from homing.thesis.report import agreement
from homing.thesis.simulation import SimulationParams
from mapdb.workers import results_in_order, spawn_process_pool

# Runs per world whose trajectories are drawn (a plot of more is unreadable).
TRACK_RUNS = 5

Tracks = dict[tuple[int, str], tuple[SimulationParams, list[np.ndarray]]]


@dataclass(frozen=True)
class SimulationRun:
    """What was simulated, and one row per (setting, method) in table order.

    Each row has exactly the keys of :data:`homing.thesis.experiments.ROW_KEYS` (rates in 0..1).
    """

    experiments: tuple[str, ...]
    worlds: tuple[int, ...]
    methods: tuple[Method, ...]
    runs: int
    seed: int
    rows: list[dict[str, Any]]

    def agreement(self) -> dict[str, Any]:
        """How many thesis-method rows agree with the paper
        (:func:`homing.thesis.report.agreement`)."""
        return agreement(self.rows)


def _tasks(
    experiments: Sequence[str],
    worlds: tuple[int, ...],
    methods: Sequence[Method],
    runs: int,
    seed: int,
) -> list[tuple[Setting, Method, int, int]]:
    """One picklable unit of work (:func:`homing.thesis.experiments.run_row`) per row, in table
    order."""
    return [
        (setting, method, runs, seed)
        for experiment in experiments
        for setting in settings(experiment, worlds)
        for method in methods
    ]


def run_simulation(
    experiments: Sequence[str],
    worlds: tuple[int, ...] = WORLDS,
    methods: tuple[Method, ...] = ("thesis", "best"),
    runs: int = 20,
    seed: int = 0,
    jobs: int = 1,
    progress: bool = False,
) -> SimulationRun:
    """Every row of the chosen experiments, in table order, on ``jobs`` processes (1: here).

    Raises ``ValueError`` naming an unknown experiment.
    """
    tasks = _tasks(experiments, worlds, methods, runs, seed)
    bar = tqdm(total=len(tasks), desc="simulating", unit="setting", disable=not progress)
    rows: list[dict[str, Any]] = []
    if jobs > 1:
        with spawn_process_pool(jobs) as pool:  # the CLI process has imported OpenCV
            for row in results_in_order(pool, [pool.submit(run_row, task) for task in tasks]):
                rows.append(row)
                bar.update()
    else:
        for task in tasks:
            rows.append(run_row(task))
            bar.update()
    bar.close()
    return SimulationRun(tuple(experiments), worlds, methods, runs, seed, rows)


def simulation_tracks(run: SimulationRun, max_runs: int = TRACK_RUNS) -> Tracks:
    """Trajectories for the plot: per (world, method), the first setting of the run's first
    experiment in that world, and the positions ``(k, 2)`` (metres) of up to ``max_runs`` runs.
    """
    experiment = run.experiments[0]
    tracks: Tracks = {}
    for world in dict.fromkeys(run.worlds):
        first = next(settings(experiment, (world,)))
        for method in run.methods:
            result = run_setting(first, method, min(run.runs, max_runs), run.seed, keep_tracks=True)
            tracks[(world, method)] = (first.params, result.tracks or [])
    return tracks
