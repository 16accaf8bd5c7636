"""The four simulation experiments of appendix B (tables B.1-B.4) and their summary rows.

Each experiment varies one parameter at a time over the values of table 4.1, every other
parameter at its default, for each world; each setting is run ``runs`` times. A row of results
has exactly the keys of :data:`ROW_KEYS` (rates in 0..1, statistics over successful runs or
``None`` when there are none).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from typing import Any, Literal

import numpy as np

from homing.thesis.controller import best_controller
from homing.thesis.simulation import (
    BatchResult,
    Controller,
    Outcome,
    SimulationParams,
    simulate_runs,
    thesis_controller,
)

Method = Literal["thesis", "best"]
METHODS: dict[str, tuple[Controller, bool]] = {
    "thesis": (thesis_controller, False),
    "best": (best_controller, True),
}
EXPERIMENTS = ("B1", "B2", "B3", "B4")
WORLDS = (1, 2, 3, 4)
ROW_KEYS = (
    "experiment",
    "world",
    "method",
    "parameter",
    "value",
    "runs",
    "success_rate",
    "fail_max_iter",
    "fail_max_proj",
    "fail_max_dist",
    "iterations_mean",
    "iterations_median",
    "iterations_std",
    "excess_distance_mean",
    "excess_distance_median",
    "excess_distance_std",
)
_OCCLUSIONS_B3 = (0, 1, 5, 10, 20, 50, 500, 700, 900, 950, 980, 990, 995)


@dataclass(frozen=True)
class Sweep:
    """One parameter of one experiment: its name in rows, its values, how it sets params."""

    parameter: str
    values: tuple[float, ...]
    apply: Callable[[SimulationParams, float], SimulationParams]


def _set(
    field_name: str, cast: type = float
) -> Callable[[SimulationParams, float], SimulationParams]:
    return lambda params, value: replace(params, **{field_name: cast(value)})


def _square(params: SimulationParams, value: float) -> SimulationParams:
    return replace(params, wall_length_x_m=float(value), wall_length_y_m=float(value))


WALL_LENGTH_X = Sweep("wall_length_m", (3, 5, 10, 15, 20, 30, 50), _set("wall_length_x_m"))
FEATURES = Sweep("features", (20, 40, 100, 500, 1000, 5000, 10000), _set("features", int))

SWEEPS: dict[str, tuple[Sweep, ...]] = {
    "B1": (
        WALL_LENGTH_X,
        Sweep("noise_sd", (0, 0.001, 0.01, 0.05, 0.1, 0.5, 1), _set("noise_sd_m")),
        FEATURES,
        Sweep("fake_features", (0, 1, 5, 10, 20, 50), _set("fake_features", int)),
        Sweep("removed_features", (0, 1, 5, 10, 20, 50), _set("removed_features", int)),
    ),
    "B2": (Sweep("wall_length_m", (3, 5, 10, 15, 20, 30, 50), _square),),
    "B3": (
        Sweep("noise_sd", (0, 0.0001, 0.0005, 0.001, 0.005, 0.01, 0.05, 0.1), _set("noise_sd_m")),
        Sweep("fake_features", _OCCLUSIONS_B3, _set("fake_features", int)),
        Sweep("removed_features", _OCCLUSIONS_B3, _set("removed_features", int)),
    ),
    "B4": (
        Sweep(
            "max_rotation_rad",
            tuple(round(k * np.pi / 10, 6) for k in range(11)),
            _set("max_rotation_rad"),
        ),
    ),
}
BASE_PARAMS: dict[str, SimulationParams] = {
    "B1": SimulationParams(),
    "B2": SimulationParams(),
    "B3": SimulationParams(start_xy_m=(-2.0, -2.0), goal_xy_m=(2.0, 2.0)),
    "B4": SimulationParams(),
}


@dataclass(frozen=True)
class Setting:
    """One (experiment, world, parameter, value) cell and the parameters it runs with."""

    experiment: str
    world: int
    parameter: str
    value: float
    params: SimulationParams


def settings(experiment: str, worlds: tuple[int, ...] = WORLDS) -> Iterator[Setting]:
    """Every setting of an experiment, world by world, in the thesis's table order."""
    if experiment not in SWEEPS:
        raise ValueError(f"unknown experiment {experiment!r}; use one of {', '.join(EXPERIMENTS)}")
    for world in worlds:
        base = replace(BASE_PARAMS[experiment], world=world)
        for sweep in SWEEPS[experiment]:
            for value in sweep.values:
                yield Setting(experiment, world, sweep.parameter, value, sweep.apply(base, value))


def setting_seed(seed: int, setting: Setting) -> np.random.SeedSequence:
    """A seed for one setting, the same for every method so they meet the same worlds."""
    parameter_index = sorted({s.parameter for sweeps in SWEEPS.values() for s in sweeps}).index(
        setting.parameter
    )
    value_key = round(setting.value * 1_000_000)
    experiment_index = EXPERIMENTS.index(setting.experiment)
    return np.random.SeedSequence(
        [seed, experiment_index, setting.world, parameter_index, value_key]
    )


def run_setting(
    setting: Setting, method: Method, runs: int, seed: int, keep_tracks: bool = False
) -> BatchResult:
    """Simulate one setting with one method."""
    controller, needs_bearings = METHODS[method]
    rng = np.random.default_rng(setting_seed(seed, setting))
    return simulate_runs(setting.params, runs, rng, controller, needs_bearings, keep_tracks)


def _stat(values: np.ndarray, how: Callable[[np.ndarray], Any]) -> float | None:
    return None if len(values) == 0 else round(float(how(values)), 4)


def summarise(setting: Setting, method: Method, result: BatchResult) -> dict[str, Any]:
    """The row of :data:`ROW_KEYS` for one setting's runs."""
    outcome = result.outcome
    runs = len(outcome)
    ok = outcome == Outcome.SUCCESS
    iterations = result.iterations[ok].astype(float)
    excess = result.excess_distance_m[ok]
    row: dict[str, Any] = {
        "experiment": setting.experiment,
        "world": setting.world,
        "method": method,
        "parameter": setting.parameter,
        "value": setting.value,
        "runs": runs,
        "success_rate": float(ok.mean()),
        "fail_max_iter": float(np.mean(outcome == Outcome.MAX_ITERATIONS)),
        "fail_max_proj": float(np.mean(outcome == Outcome.MAX_EMPTY_PROJECTIONS)),
        "fail_max_dist": float(np.mean(outcome == Outcome.MAX_DISTANCE)),
    }
    for name, values in (("iterations", iterations), ("excess_distance", excess)):
        row[f"{name}_mean"] = _stat(values, np.mean)
        row[f"{name}_median"] = _stat(values, np.median)
        row[f"{name}_std"] = _stat(values, lambda v: np.std(v, ddof=1) if len(v) > 1 else 0.0)
    return row


def run_row(args: tuple[Setting, Method, int, int]) -> dict[str, Any]:
    """Run and summarise one setting (a picklable unit of work for a process pool)."""
    setting, method, runs, seed = args
    return summarise(setting, method, run_setting(setting, method, runs, seed))
