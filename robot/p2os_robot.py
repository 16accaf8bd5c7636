"""A :class:`~localizer.robot_protocol.Robot` from a base and a camera, and the simulated camera
bound to a simulated base.

:class:`BaseWithCamera` joins a base (turn, drive, odometry, stop: :class:`robot.p2os_base.
P2osBase`) and anything that captures a panorama (:class:`localizer.robot_protocol.Camera`).
:class:`SimCamera` renders the panorama at a pose read when it captures, e.g. the true pose of a
:class:`robot.p2os_sim.P2osSimulator`: with the simulator in the same process this closes the
whole loop over the real serial protocol.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from typing import Protocol

import cv2

from localizer.robot_protocol import Camera, Capture, MoveResult, Pose2D
from robot.conditions import DEFAULT_CONDITION, Condition
from robot.render import PanoramaCamera, render_panorama
from robot.scene import build_scene
from robot.world import World


class Base(Protocol):
    """The motion part of a Robot."""

    def move(self, turn_rad: float, forward_m: float) -> MoveResult: ...

    def odometry(self) -> Pose2D: ...

    def stop(self) -> None: ...


class NoCamera:
    """A base without a camera: capturing is an error saying so."""

    def __init__(self, what: str) -> None:
        self.what = what

    def capture(self) -> Capture:
        raise RuntimeError(f"{self.what} has no camera bound to it")


class BaseWithCamera:
    """A Robot: motion and odometry from ``base``, panoramas from ``camera``."""

    def __init__(self, base: Base, camera: Camera) -> None:
        self.base = base
        self.camera = camera

    def capture(self) -> Capture:
        return self.camera.capture()

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        return self.base.move(turn_rad, forward_m)

    def odometry(self) -> Pose2D:
        return self.base.odometry()

    def stop(self) -> None:
        self.base.stop()


class SimCamera:
    """Renders ``world`` (with its condition objects already in it) at ``pose_fn()``, the
    building-frame pose at capture time; BGR unless ``grey``, sensor noise seeded by ``seed``
    and the capture count."""

    def __init__(
        self,
        world: World,
        pose_fn: Callable[[], Pose2D],
        camera: PanoramaCamera | None = None,
        condition: Condition | None = None,
        seed: int = 0,
        grey: bool = False,
    ) -> None:
        self.world = world
        self.pose_fn = pose_fn
        self.camera = camera or PanoramaCamera(height_m=world.camera_height_m)
        self.condition = condition or DEFAULT_CONDITION
        self.seed = seed
        self.grey = grey
        self._scene = build_scene(world)
        self._count = itertools.count()

    def capture(self) -> Capture:
        image = render_panorama(
            self._scene,
            self.pose_fn(),
            self.camera,
            self.condition,
            seed=(self.seed, 17, next(self._count)),
            grey=self.grey,
        )
        if not self.grey:
            image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        return Capture(image, time.time(), f"sim-camera:{self.world.name}")
