"""Simulation only: the client side of :mod:`toploc.nodes.sim_truth`. :class:`TruePose` holds the
latest ``sim/true_pose`` received (:func:`subscribe_true_pose`) and is the ``pose_fn`` of a
:class:`robot.p2os_robot.SimCamera`: capturing fails with a clear error when no pose came yet
or the last is older than ``max_age_s``."""

from __future__ import annotations

import math
import threading
import time

import zenoh

from robot.world import Pose2D
from toploc import bus
from toploc.bus.schemas import TRUE_POSE

MAX_AGE_S = 1.0


class TruePose:
    """The latest ``sim/true_pose`` of world ``world``: :meth:`update` on each message,
    :meth:`__call__` for the pose (a ``SimCamera``'s ``pose_fn``)."""

    def __init__(self, world: str, robot_id: str, max_age_s: float = MAX_AGE_S) -> None:
        self.world = world
        self.robot_id = robot_id
        self.max_age_s = max_age_s
        self._lock = threading.Lock()
        self._latest: tuple[Pose2D, float] | None = None
        self._problem: str | None = None

    def update(self, payload: bytes | None) -> None:
        """Take a ``sim/true_pose`` message (a malformed one, or one of another world, is kept
        as the error the next capture reports)."""
        where = bus.key(self.robot_id, bus.SIM_TRUE_POSE)
        try:
            message = TRUE_POSE.decode(where, payload)
            if message["world"] != self.world:
                raise bus.BusMessageError(
                    f"{where}: the simulator runs world {message['world']!r}, this camera "
                    f"renders {self.world!r} (--sim-world)"
                )
            pose = Pose2D(message["x_m"], message["y_m"], math.radians(message["heading_deg"]))
        except bus.BusMessageError as error:
            with self._lock:
                self._problem = str(error)
            return
        with self._lock:
            self._latest, self._problem = (pose, time.monotonic()), None

    def __call__(self) -> Pose2D:
        """The latest true pose; ``RuntimeError`` saying why there is none."""
        where = bus.key(self.robot_id, bus.SIM_TRUE_POSE)
        with self._lock:
            latest, problem = self._latest, self._problem
        if problem is not None:
            raise RuntimeError(problem)
        if latest is None:
            raise RuntimeError(
                f"no true pose on {where} yet: the sim camera renders where the simulator "
                f"says the base is (toploc sim p2os --robot-id {self.robot_id} on this bus)"
            )
        age_s = time.monotonic() - latest[1]
        if age_s > self.max_age_s:
            raise RuntimeError(
                f"the last true pose on {where} is {age_s:.1f} s old (at most "
                f"{self.max_age_s:g} s): is the simulator still running?"
            )
        return latest[0]


def subscribe_true_pose(session: zenoh.Session, true_pose: TruePose) -> zenoh.Subscriber:
    """Feed ``true_pose`` from ``sim/true_pose`` on ``session``; undeclare the result to stop."""

    def on_sample(sample: zenoh.Sample) -> None:
        true_pose.update(sample.payload.to_bytes())

    return session.declare_subscriber(
        bus.key(true_pose.robot_id, bus.SIM_TRUE_POSE),
        zenoh.handlers.Callback(on_sample, indirect=True),
    )
