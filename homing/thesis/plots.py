"""Plots of the simulation: trajectories and success curves against the thesis (matplotlib)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only: toploc runs headless on robots and CI
import matplotlib.pyplot as plt
import numpy as np

from homing.thesis.reference import reference_key, thesis_rows
from homing.thesis.simulation import WORLD_WALLS, SimulationParams

_WORLD_COLOURS = {1: "tab:blue", 2: "tab:orange", 3: "tab:green", 4: "tab:red"}


def _draw_walls(ax: Any, params: SimulationParams) -> None:
    hx, hy = params.wall_length_x_m / 2, params.wall_length_y_m / 2
    segments = {
        1: ((-hx, hx), (-hy, -hy)),
        2: ((hx, hx), (-hy, hy)),
        3: ((-hx, hx), (hy, hy)),
        4: ((-hx, -hx), (-hy, hy)),
    }
    for wall in WORLD_WALLS[params.world]:
        ax.plot(*segments[wall], color="black", linewidth=3)


def plot_simulation(
    rows: Sequence[dict[str, Any]],
    tracks: dict[tuple[int, str], tuple[SimulationParams, list[np.ndarray]]],
    path: Path,
) -> Path:
    """Write a PNG: one trajectory panel per world, one success panel per swept parameter.

    ``tracks`` maps (world, method) to the setting and its runs' positions (k, 2) in metres.
    """
    sweeps = list(dict.fromkeys((r["experiment"], r["parameter"]) for r in rows))
    worlds = sorted({world for world, _ in tracks})
    n_panels = len(worlds) + len(sweeps)
    cols = 4
    fig, axes = plt.subplots(
        (n_panels + cols - 1) // cols,
        cols,
        figsize=(4.2 * cols, 3.8 * ((n_panels + cols - 1) // cols)),
        squeeze=False,
    )
    flat = list(axes.ravel())
    for ax, world in zip(flat, worlds, strict=False):
        for method, style in (("thesis", "-"), ("best", "--")):
            if (world, method) not in tracks:
                continue
            params, runs = tracks[(world, method)]
            for i, track in enumerate(runs):
                ax.plot(
                    *track.T,
                    style,
                    color="tab:blue" if method == "thesis" else "tab:purple",
                    linewidth=0.8,
                    alpha=0.7,
                    label=method if i == 0 else None,
                )
        _draw_walls(ax, params)
        ax.plot(*params.start_xy_m, "ks", label="start")
        ax.plot(*params.goal_xy_m, "g*", markersize=12, label="goal")
        ax.set_title(f"world {world}: trajectories")
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.legend(fontsize=7)
    reference = thesis_rows()
    for ax, (experiment, parameter) in zip(flat[len(worlds) :], sweeps, strict=False):
        for world in sorted({r["world"] for r in rows}):
            colour = _WORLD_COLOURS[world]
            for method, style in (("thesis", "-o"), ("best", "--^")):
                sel = [
                    r
                    for r in rows
                    if (r["experiment"], r["parameter"], r["world"], r["method"])
                    == (experiment, parameter, world, method)
                ]
                if sel:
                    ax.plot(
                        range(len(sel)),
                        [r["success_rate"] for r in sel],
                        style,
                        color=colour,
                        markersize=3,
                        label=f"w{world} {method}",
                    )
            paper = [
                reference.get(reference_key(experiment, world, parameter, r["value"]), {}).get(
                    "success_rate"
                )
                for r in rows
                if (r["experiment"], r["parameter"], r["world"], r["method"])
                == (experiment, parameter, world, "thesis")
            ]
            if paper:
                ax.plot(
                    range(len(paper)),
                    [np.nan if p is None else p for p in paper],
                    ":x",
                    color=colour,
                    markersize=4,
                    label=f"w{world} paper",
                )
        values = [
            r["value"]
            for r in rows
            if (r["experiment"], r["parameter"], r["world"], r["method"])
            == (experiment, parameter, rows[0]["world"], rows[0]["method"])
        ]
        ax.set_xticks(range(len(values)), [f"{v:g}" for v in values], rotation=60, fontsize=7)
        ax.set_ylim(-0.05, 1.05)
        ax.set_title(f"{experiment}: success vs {parameter}")
        ax.set_ylabel("success rate")
        ax.legend(fontsize=5, ncol=3)
    for ax in flat[n_panels:]:
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
