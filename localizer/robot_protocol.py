"""What toploc needs from a robot: capture a panorama, turn and drive, report odometry; and
the one planar pose type (:class:`Pose2D`) that odometry, room frames and simulated worlds share.

The simulated robot (``robot.sim_robot``) and a real base (Pioneer over pyserial, with a
camera) both provide :class:`Robot`; the active localizer and the Zenoh robot node use only
this protocol. A camera that is a device of its own (a 360° webcam, photos on a pan-tilt unit,
a mirror camera; ``robot.camera_sources``) provides :class:`Camera`, and the robot node serves
it beside the base.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class Capture:
    """A cylindrical panorama (``image``: uint8, H x W grey or H x W x 3 BGR) and when it was
    taken (``stamp_s``, seconds, the robot's clock). Column 0 looks along the robot's heading."""

    image: np.ndarray
    stamp_s: float
    source: str


@dataclass(frozen=True)
class Pose2D:
    """A planar robot pose: position ``x_m``, ``y_m`` (metres) and heading ``heading_rad``
    (radians, counter-clockwise from the frame's +x axis; REP-103).

    The frame is the one the holder's name and docstring say, never a second type: the
    odometry frame for :meth:`Robot.odometry` (dead-reckoned, drifting over time), a room's
    frame for a place, the building frame of a simulated world (:mod:`robot.world`) for the
    true pose of a simulated robot.
    """

    x_m: float
    y_m: float
    heading_rad: float = 0.0


@dataclass(frozen=True)
class MoveResult:
    """What a move did: the turn and the distance actually made; ``bumped`` if it was stopped
    by contact before the commanded distance."""

    turned_rad: float
    moved_m: float
    bumped: bool


class Camera(Protocol):
    """A panoramic camera on its own: a robot is then a base plus a Camera."""

    def capture(self) -> Capture:
        """Take a panorama now; raise ``ValueError`` (one line naming the source) if it cannot."""
        ...


class Robot(Protocol):
    """A mobile robot with a panoramic camera."""

    def capture(self) -> Capture:
        """Take a panorama now."""
        ...

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        """Turn in place by ``turn_rad`` (counter-clockwise positive), then drive ``forward_m``
        straight ahead (negative: backwards)."""
        ...

    def odometry(self) -> Pose2D:
        """The current dead-reckoned pose, in the odometry frame."""
        ...

    def stop(self) -> None:
        """Stop the base now; called from another thread while :meth:`move` runs, which then
        returns early with what was done."""
        ...
