"""Plots of homing on images: home vectors to one home (figure 5.6), alignment error by distance
(figure 5.4). Matplotlib with the Agg backend; files only."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: toploc runs headless on robots and CI
import matplotlib.pyplot as plt
import numpy as np

from homing.thesis.evaluation import DistanceBin


def plot_home_vectors(
    positions_m: np.ndarray,
    home_index: int,
    home_direction_room_rad: np.ndarray,
    path: Path,
    title: str = "",
    labels: Sequence[str] | None = None,
) -> Path:
    """Write a PNG map of one room: places, the home (red) and each place's home vector.

    ``positions_m`` (n, 2) are in the room frame (metres); ``home_direction_room_rad`` (n,) is
    each place's home direction in the room frame (NaN: none, and ignored at the home itself).
    Grey dashed lines show the true directions. Returns ``path``.
    """
    positions = np.asarray(positions_m, dtype=float)
    directions = np.asarray(home_direction_room_rad, dtype=float)
    span = float(np.ptp(positions, axis=0).max()) if len(positions) > 1 else 1.0
    length = 0.08 * max(span, 1.0)
    fig, ax = plt.subplots(figsize=(6.5, 6.5))
    home = positions[home_index]
    for k, (p, d) in enumerate(zip(positions, directions, strict=True)):
        if k == home_index:
            continue
        ax.plot(*np.column_stack([p, home]), color="0.8", linestyle="--", linewidth=0.7)
        if np.isfinite(d):
            ax.arrow(
                float(p[0]),
                float(p[1]),
                length * np.cos(d),
                length * np.sin(d),
                color="tab:red",
                width=0.004 * span,
                head_width=0.025 * span,
                length_includes_head=True,
            )
    ax.scatter(
        positions[:, 0], positions[:, 1], s=30, facecolors="white", edgecolors="black", zorder=3
    )
    ax.scatter(home[0], home[1], s=90, color="tab:red", zorder=4, label="home")
    if labels is not None:
        for p, text in zip(positions, labels, strict=True):
            ax.annotate(text, p, textcoords="offset points", xytext=(3, 3), fontsize=6)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, room frame)")
    ax.set_ylabel("y (m, room frame)")
    ax.set_title(title or "home vectors")
    ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_alignment(
    bins: Mapping[str, list[DistanceBin]],
    errors_deg: Mapping[str, np.ndarray],
    path: Path,
    title: str = "",
) -> Path:
    """Write a PNG: mean ± standard error of each compass by distance, and error histograms."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.2))
    for name, rows in bins.items():
        centre = [(b.low_m + b.high_m) / 2 for b in rows]
        mean = [b.mean_deg for b in rows]
        sem = [b.std_deg / np.sqrt(b.n) for b in rows]
        left.errorbar(centre, mean, yerr=sem, marker="o", capsize=3, label=name)
    left.set_xlabel("distance between panoramas (m)")
    left.set_ylabel("alignment error (deg)")
    left.set_ylim(0, 180)
    left.legend()
    left.set_title(title or "alignment error by distance")
    edges = np.linspace(0, 180, 19)
    for name, errors in errors_deg.items():
        finite = np.asarray(errors)[np.isfinite(errors)]
        right.hist(finite, bins=edges, histtype="step", linewidth=1.5, label=name)
    right.set_xlabel("alignment error (deg)")
    right.set_ylabel("pairs")
    right.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
