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

:class:`SimTruthNode` serves both beside a :class:`robot.p2os_sim.P2osSimulator`;
:class:`TruePose` holds the latest pose received (:func:`subscribe_true_pose`) and is the
``pose_fn`` of a :class:`robot.p2os_robot.SimCamera`: capturing fails with a clear error when
no pose came yet or the last is older than ``max_age_s``.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any

import numpy as np
import zenoh

from localizer.robot_protocol import Pose2D
from robot.p2os_sim import P2osSimulator
from robot.sim_robot import random_free_pose
from toploc import bus

PERIOD_S = 0.1
MAX_AGE_S = 1.0
TRUE_POSE_KIND = "true_pose"
KIDNAP_KIND = "kidnap"
TRUE_POSE_FIELDS: dict[str, bus.FieldType] = {
    "x_m": float,
    "y_m": float,
    "heading_deg": float,
    "world": str,
    "room": (str, type(None)),
    "stamp": float,
}


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


def open_when_up(
    config: bus.BusConfig, stop: threading.Event, retry_s: float = 0.5
) -> zenoh.Session | None:
    """A session of ``config`` (a Zenoh client: it cannot open before the service it connects
    to listens), tried every ``retry_s`` until it opens; None if ``stop`` is set first."""
    while True:
        try:
            return bus.open_session(config)
        except bus.BusError:
            if stop.wait(retry_s):
                return None


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
        self._publisher.put(bus.encode(TRUE_POSE_KIND, fields))
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
        request = bus.decode(where, payload, {"room": str}, kind=KIDNAP_KIND, max_bytes=4096)
        room = request["room"]
        if room not in {r.name for r in self.sim.world.rooms}:
            raise bus.BusMessageError(f"{where}: room {room!r} is not in {self.sim.world.name!r}")
        self.sim.teleport(random_free_pose(self.sim.obstacles, room, self._rng))
        return bus.Reply(bus.encode(TRUE_POSE_KIND, self.publish()))


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
            message = bus.decode(where, payload, TRUE_POSE_FIELDS, kind=TRUE_POSE_KIND)
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
