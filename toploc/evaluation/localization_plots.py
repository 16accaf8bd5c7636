"""Plots of single-shot localization: calibration of the stated top-room probability (a
reliability diagram) and the five outcomes. Matplotlib with the Agg backend; files only."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: toploc runs headless on robots and CI
import matplotlib.pyplot as plt

from toploc.evaluation.reliability import Reliability

OUTCOME_COLOURS = {
    "right_localized": "tab:green",
    "right_ambiguous": "yellowgreen",
    "wrong_localized": "tab:red",
    "wrong_ambiguous": "tab:orange",
    "lost": "0.6",
}
"""One colour per outcome; confidently wrong in red."""


def plot_localization(
    calibration: Reliability, outcomes: Mapping[str, int], path: Path, title: str = ""
) -> Path:
    """Write a PNG: left, each bin's fraction right against its mean stated probability (0..1)
    with the diagonal of perfect calibration, the bin edges and each bin's count; right, the
    count of each of the five outcomes. Returns ``path``."""
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.5))
    left.plot([0, 1], [0, 1], color="0.5", linestyle="--", linewidth=1, label="calibrated")
    for b in calibration.bins:
        left.axvline(b.low, color="0.9", linewidth=0.8, zorder=0)
    filled = [b for b in calibration.bins if b.mean_stated is not None]
    stated = [b.mean_stated for b in filled]
    right_share = [b.fraction_right for b in filled]
    left.plot(stated, right_share, "o-", color="tab:blue", label="toploc")
    for b in filled:
        left.annotate(
            f"n={b.n}",
            (b.mean_stated or 0.0, b.fraction_right or 0.0),
            textcoords="offset points",
            xytext=(4, -12),
            fontsize=8,
        )
    left.set_xlim(0, 1.02)
    left.set_ylim(-0.02, 1.05)
    left.set_xlabel("stated probability of the top room (bin mean)")
    left.set_ylabel("fraction right (lost = not right)")
    left.set_title(f"{title or 'calibration'}; Brier {calibration.brier:.3f}")
    left.legend(loc="upper left", fontsize=8)
    names = list(outcomes)
    counts = [outcomes[name] for name in names]
    bars = right.bar(
        [name.replace("_", "\n") for name in names],
        counts,
        color=[OUTCOME_COLOURS.get(name, "tab:blue") for name in names],
    )
    right.bar_label(bars, fontsize=8)
    right.set_ylabel("queries")
    right.set_title(f"outcomes of {sum(counts)} queries")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
