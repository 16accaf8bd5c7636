"""Reliability of stated probabilities: does a room stated at p turn out right a fraction p
of the time? A reliability table over bins of stated probability, and the Brier score.

Pure numpy: stated probabilities (0..1) and whether each answer was right in, numbers out.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

RELIABILITY_EDGES = (0.0, 0.5, 0.7, 0.9, 0.99, 1.0)
"""Bin edges of stated probability: ``[low, high)``, the last bin closed at 1."""


@dataclass(frozen=True)
class ReliabilityBin:
    """The answers stated at a probability in ``[low, high)`` (the last bin includes 1):
    how many, their mean stated probability and the fraction right (both ``None`` if empty)."""

    low: float
    high: float
    n: int
    mean_stated: float | None
    fraction_right: float | None

    def to_json(self) -> dict[str, Any]:
        return {
            "low": self.low,
            "high": self.high,
            "n": self.n,
            "mean_stated": self.mean_stated,
            "fraction_right": self.fraction_right,
        }


@dataclass(frozen=True)
class Reliability:
    """The reliability table and the Brier score (mean squared gap between stated probability
    and 1 if right else 0: 0 is perfect, 0.25 is always stating 0.5)."""

    bins: tuple[ReliabilityBin, ...]
    brier: float

    def to_json(self) -> dict[str, Any]:
        return {"bins": [b.to_json() for b in self.bins], "brier": self.brier}


def _checked(stated: Sequence[float], right: Sequence[bool]) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(stated, dtype=float)
    hit = np.asarray(right, dtype=bool)
    if p.ndim != 1 or p.shape != hit.shape or p.size == 0:
        raise ValueError(
            f"need as many stated probabilities as answers (at least one), "
            f"got shapes {p.shape} and {hit.shape}"
        )
    if not np.all((p >= 0.0) & (p <= 1.0)):
        raise ValueError(f"stated probabilities must be in 0..1, got {p[(p < 0) | (p > 1)]}")
    return p, hit


def brier_score(stated: Sequence[float], right: Sequence[bool]) -> float:
    """``mean((p - right)^2)`` over the answers (0..1, lower is better)."""
    p, hit = _checked(stated, right)
    return float(np.mean((p - hit) ** 2))


def reliability_bins(
    stated: Sequence[float],
    right: Sequence[bool],
    edges: Sequence[float] = RELIABILITY_EDGES,
) -> tuple[ReliabilityBin, ...]:
    """The answers binned by stated probability (``edges`` ascending, from 0 to 1)."""
    p, hit = _checked(stated, right)
    index = np.clip(np.searchsorted(edges, p, side="right") - 1, 0, len(edges) - 2)
    bins = []
    for k in range(len(edges) - 1):
        mine = index == k
        n = int(mine.sum())
        bins.append(
            ReliabilityBin(
                low=float(edges[k]),
                high=float(edges[k + 1]),
                n=n,
                mean_stated=float(p[mine].mean()) if n else None,
                fraction_right=float(hit[mine].mean()) if n else None,
            )
        )
    return tuple(bins)


def reliability(stated: Sequence[float], right: Sequence[bool]) -> Reliability:
    """The reliability table over :data:`RELIABILITY_EDGES` and the Brier score."""
    return Reliability(reliability_bins(stated, right), brier_score(stated, right))
