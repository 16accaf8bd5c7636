"""The fingerprint of a panorama: its keypoints, their bearings and descriptors for one detector."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np


@dataclass(frozen=True)
class Fingerprint:
    """Features of one panorama found by one detector.

    ``keypoints_xy`` are OpenCV pixel coordinates (x right, y down; pixel centres at integers) on
    the cylindrical panorama of ``image_width_px`` x ``image_height_px``. ``bearings_rad`` are
    robot-frame azimuths (REP-103: counter-clockwise positive, 0 along the heading), which for a
    cylindrical panorama is ``-2*pi*x/W`` wrapped to (-pi, pi]. ``descriptors`` are float32 rows
    (128 values for SIFT). ``params`` records how they were extracted (for the map database).
    """

    detector: str
    image_width_px: int
    image_height_px: int
    keypoints_xy: np.ndarray
    bearings_rad: np.ndarray
    descriptors: np.ndarray
    params: Mapping[str, float | int | str | bool] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.bearings_rad)
        if self.keypoints_xy.shape != (n, 2):
            raise ValueError(
                f"keypoints_xy must have shape ({n}, 2) to match {n} bearings, "
                f"got {self.keypoints_xy.shape}"
            )
        if len(self.descriptors) != n:
            raise ValueError(f"descriptors has {len(self.descriptors)} rows for {n} bearings")

    @property
    def n(self) -> int:
        """Number of keypoints."""
        return len(self.bearings_rad)

    @classmethod
    def empty(
        cls,
        detector: str,
        image_width_px: int,
        image_height_px: int,
        descriptor_size: int = 128,
        params: Mapping[str, float | int | str | bool] | None = None,
    ) -> Fingerprint:
        """A fingerprint with no keypoints (e.g. a blank wall): 0 rows, float32 descriptors."""
        return cls(
            detector=detector,
            image_width_px=image_width_px,
            image_height_px=image_height_px,
            keypoints_xy=np.zeros((0, 2), dtype=np.float64),
            bearings_rad=np.zeros(0, dtype=np.float64),
            descriptors=np.zeros((0, descriptor_size), dtype=np.float32),
            params=dict(params or {}),
        )

    def select(self, mask: np.ndarray) -> Fingerprint:
        """The keypoints where boolean ``mask`` (or an index array) selects, other fields kept."""
        mask = np.asarray(mask)
        if mask.dtype == bool and mask.shape != (self.n,):
            raise ValueError(f"boolean mask must have shape ({self.n},), got {mask.shape}")
        return replace(
            self,
            keypoints_xy=self.keypoints_xy[mask],
            bearings_rad=self.bearings_rad[mask],
            descriptors=self.descriptors[mask],
        )
