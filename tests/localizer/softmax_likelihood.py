"""A likelihood for tests whose synthetic inlier counts have no map to be calibrated on.

``L_r = (1 - floor) * softmax(n_r / temperature_inliers)_r + floor / N``, flat below
``min_inliers``: it depends only on count differences (a lead of 10 inliers counts the same at
any level). It is not toploc's model, which is the calibrated
:class:`localizer.likelihood.RatioLikelihood`; it only satisfies the same protocol,
:class:`localizer.likelihood.Likelihood`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import softmax


@dataclass(frozen=True)
class SoftmaxLikelihood:
    """The softmax model; ``count`` names the evidence count it reads (raw inliers)."""

    temperature_inliers: float = 15.0
    floor: float = 0.05
    min_inliers: int = 20
    count: str = "inliers"

    def from_room_inliers(self, room_inliers: np.ndarray) -> np.ndarray:
        """Likelihood per room (sums to 1) from the best inlier count per room, shape (N,)."""
        counts = np.asarray(room_inliers, dtype=float)
        if counts.max() < self.min_inliers:
            return np.full(counts.size, 1.0 / counts.size)
        sharp = softmax(counts / self.temperature_inliers)
        return (1.0 - self.floor) * sharp + self.floor / counts.size
