"""Simulation only: the simulated base's true pose on the bus, so that a sim camera in another
process renders where the simulated base really is, and a way to kidnap the simulated base.

A real robot has no such keys: nothing on a real robot knows its true pose. They exist so that
``toploc sim p2os`` (a simulated Pioneer on a pty, its own process) and ``toploc serve --robot
p2os:PORT --source sim`` (the service, driving that pty like a real base) can be two processes
joined only by the pty and Zenoh, as a real base and its service are.

Keys under ``toploc/<robot_id>/``:

- ``sim/true_pose`` (publication, every ``period_s`` and after each kidnap): ``{schema, kind:
  "true_pose", x_m, y_m, heading_deg, world, room, stamp}``: the building frame of the world
  (``room``: the room it is in, or null between rooms; ``stamp``: seconds since the epoch).
- ``sim/kidnap`` (queryable): ``{kind: "kidnap", room}``: the base is carried to a seeded random
  free pose in ``room`` with a random heading and its wheels stopped; the odometry is not told
  (that is what a kidnap is). Replies with the new true pose (the ``sim/true_pose`` fields).

:class:`SimTruthNode` serves both beside a :class:`robot.p2os_sim.P2osSimulator`; the client
side, :class:`~toploc.bus.clients.sim_truth.TruePose` (the ``pose_fn`` of a sim camera) and
:func:`~toploc.bus.clients.sim_truth.subscribe_true_pose`, is also importable from here.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any

import numpy as np
import zenoh

from robot.p2os_sim import P2osSimulator
from robot.sim_robot import random_free_pose
from toploc import bus
from toploc.bus.clients.sim_truth import MAX_AGE_S, TruePose, subscribe_true_pose
from toploc.bus.schemas import KIDNAP, TRUE_POSE

__all__ = [
    "MAX_AGE_S",
    "PERIOD_S",
    "SimTruthNode",
    "TruePose",
    "subscribe_true_pose",
    "true_pose_fields",
]

PERIOD_S = 0.1


def true_pose_fields(sim: P2osSimulator) -> dict[str, Any]:
    """The ``sim/true_pose`` fields of ``sim`` now."""
    pose = sim.true_pose
    room = sim.world.room_at(pose.x_m, pose.y_m)
    return {
        "x_m": pose.x_m,
        "y_m": pose.y_m,
        "heading_deg": math.degrees(pose.heading_rad),
        "world": sim.world.name,
        "room": None if room is None else room.name,
        "stamp": time.time(),
    }


class SimTruthNode:
    """Publish ``sim``'s true pose on ``sim/true_pose`` every ``period_s`` and serve
    ``sim/kidnap`` (kidnap poses seeded by ``seed``); ``close()`` (or ``with``)."""

    def __init__(
        self,
        session: zenoh.Session,
        robot_id: str,
        sim: P2osSimulator,
        period_s: float = PERIOD_S,
        seed: int = 0,
    ) -> None:
        self.robot_id = bus.check_robot_id(robot_id)
        self.sim = sim
        self.period_s = period_s
        self._rng = np.random.default_rng([seed, 29])
        self._publisher = session.declare_publisher(bus.key(robot_id, bus.SIM_TRUE_POSE))
        self._entities: list[Any] = [
            bus.serve(session, bus.key(robot_id, bus.SIM_KIDNAP), self._on_kidnap),
            self._publisher,
        ]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sim-true-pose", daemon=True)
        self._thread.start()

    def publish(self) -> dict[str, Any]:
        """Publish the true pose now; returns its fields."""
        fields = true_pose_fields(self.sim)
        self._publisher.put(TRUE_POSE.encode(fields))
        return fields

    def close(self) -> None:
        """Stop publishing and undeclare (the session stays open)."""
        self._stop.set()
        self._thread.join(2.0)
        bus.undeclare_all(self._entities)

    def __enter__(self) -> SimTruthNode:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            try:
                self.publish()
            except zenoh.ZError:  # the session is closing
                return

    def _on_kidnap(self, payload: bytes | None) -> bus.Reply:
        where = bus.key(self.robot_id, bus.SIM_KIDNAP)
        request = KIDNAP.decode(where, payload, max_bytes=4096)
        room = request["room"]
        if room not in {r.name for r in self.sim.world.rooms}:
            raise bus.BusMessageError(f"{where}: room {room!r} is not in {self.sim.world.name!r}")
        self.sim.teleport(random_free_pose(self.sim.obstacles, room, self._rng))
        return bus.Reply(TRUE_POSE.encode(self.publish()))
