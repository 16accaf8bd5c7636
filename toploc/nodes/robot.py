"""The robot on the Zenoh bus: :class:`RobotNode` serves a :class:`~localizer.robot_protocol.Robot`
(and, if given, a separate :class:`~localizer.robot_protocol.Camera` for its captures),
:class:`~toploc.bus.clients.robot.RemoteRobot` (also importable from here) is a Robot that talks
to such a node.

Keys under ``toploc/<robot_id>/``:

- ``camera/capture``, ``camera/panorama`` and the token ``alive/camera``: served by the
  :class:`~toploc.nodes.camera.CameraNode` the robot node composes (unless ``serve_camera`` is
  false: a camera node of its own then serves them, ``toploc node camera``).
- ``base/cmd`` (queryable): ``{kind: "cmd", turn_deg, forward_m}`` -> ``{turned_deg, moved_m,
  bumped, odom}`` once the move is done (``odom``: the ``base/odom`` fields after the move); a
  malformed command, or one beyond the node's :class:`~toploc.limits.Limits`, gets an error
  reply and the robot does not move. A move still running after ``move_timeout_s`` is stopped
  and answered with an error.
- ``base/stop`` (queryable): stop the base now (also during a move); replies ``{stopped: true}``.
- ``base/odom`` (publication after each move, and queryable): ``{x_m, y_m, heading_deg, stamp}``
  in the odometry frame (REP-103).
- ``base/bumpers`` (publication after each move): ``{bumped, stamp}``.
- liveliness token ``alive/robot``.

Calls into the robot are serialized with a lock (one serial line, one camera): an odometry
query waits for a move in progress. ``base/stop`` does not wait for it.
"""

from __future__ import annotations

import concurrent.futures
import math
import threading
import time
from typing import Any

import zenoh

from localizer.robot_protocol import Camera, MoveResult, Pose2D, Robot
from toploc import bus
from toploc.bus.clients.robot import RemoteRobot
from toploc.bus.messages import odometry_fields
from toploc.bus.schemas import BUMPERS, CMD, MOVE, ODOM, STOPPED
from toploc.limits import Limits
from toploc.nodes.camera import CameraNode
from toploc.nodes.node import Node

__all__ = ["NODE_NAME", "MoveStoppedError", "RemoteRobot", "RobotNode", "check_command"]

NODE_NAME = "robot"


def check_command(where: str, command: dict[str, Any], limits: Limits) -> None:
    """Raise BusMessageError (prefixed ``where``) for a ``base/cmd`` beyond ``limits``."""
    if abs(command["forward_m"]) > limits.max_forward_m:
        raise bus.BusMessageError(
            f"{where}: forward_m {command['forward_m']!r} is beyond the limit of "
            f"{limits.max_forward_m:g} m per command"
        )
    if abs(command["turn_deg"]) > limits.max_turn_deg:
        raise bus.BusMessageError(
            f"{where}: turn_deg {command['turn_deg']!r} is beyond the limit of "
            f"{limits.max_turn_deg:g}° per command"
        )


class MoveStoppedError(RuntimeError):
    """A move was cancelled by ``base/stop`` (or its timeout) before it started."""


class RobotNode(Node):
    """Serve ``robot`` on the bus under ``toploc/<robot_id>/`` within ``limits``; ``close()``
    (or ``with``). ``camera``: where ``camera/capture`` takes its panoramas (a camera that is
    not the robot's own, e.g. ``robot.camera_sources``); None: ``robot.capture``.
    ``serve_camera`` false: the base only (a camera node serves the captures)."""

    def __init__(
        self,
        session: zenoh.Session,
        robot_id: str,
        robot: Robot,
        limits: Limits | None = None,
        camera: Camera | None = None,
        serve_camera: bool = True,
    ) -> None:
        super().__init__(session, robot_id, NODE_NAME)
        self.robot = robot
        self.camera: Camera = robot if camera is None else camera
        self.limits = limits or Limits()
        self._lock = threading.Lock()
        self.camera_node = None
        if serve_camera:  # first: a camera node already running fails it before anything else
            self.camera_node = CameraNode(
                session, robot_id, self.camera, self.limits, self._heading_deg, self._lock
            )
        # One thread runs the moves, so that a move past its timeout can be stopped and answered.
        self._mover = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="base-move")
        self._stops = 0  # counts base/stop; a move checks only that it changed
        k = self.key
        self._odom = session.declare_publisher(k(bus.BASE_ODOM))
        self._bumpers = session.declare_publisher(k(bus.BASE_BUMPERS))
        self.entities += [
            bus.serve(session, k(bus.BASE_CMD), self._on_cmd),
            bus.serve(session, k(bus.BASE_STOP), self._on_stop),
            bus.serve(session, k(bus.BASE_ODOM), self._on_odom),
            self._odom,
            self._bumpers,
            session.liveliness().declare_token(bus.alive_key(robot_id, NODE_NAME)),
        ]

    def close(self) -> None:
        """Undeclare everything and stop the base (the session stays open)."""
        if self.camera_node is not None:
            self.camera_node.close()
        super().close()
        self.robot.stop()
        self._mover.shutdown(wait=False, cancel_futures=True)

    def _heading_deg(self) -> float:
        return math.degrees(self.robot.odometry().heading_rad)

    def _move(
        self, turn_deg: float, forward_m: float, stops_seen: int
    ) -> tuple[MoveResult, Pose2D]:
        with self._lock:  # a capture may hold it for seconds: a stop meanwhile cancels the move
            if self._stops != stops_seen:
                raise MoveStoppedError("base/stop came before the move started: not moved")
            return self.robot.move(math.radians(turn_deg), forward_m), self.robot.odometry()

    def _on_cmd(self, payload: bytes | None) -> bus.Reply:
        where = self.key(bus.BASE_CMD)
        limits = self.limits
        command = CMD.decode(
            where, payload, True, limits.max_request_bytes, limits.max_string_chars
        )
        check_command(where, command, self.limits)
        running = self._mover.submit(
            self._move, command["turn_deg"], command["forward_m"], self._stops
        )
        try:
            result, odometry = running.result(timeout=self.limits.move_timeout_s)
        except concurrent.futures.TimeoutError:
            self._stops += 1  # the move, if it has not started, never will
            running.cancel()
            self.robot.stop()
            raise TimeoutError(
                f"{where}: the move did not finish within {self.limits.move_timeout_s:g} s; "
                "the base was stopped"
            ) from None
        odom = odometry_fields(odometry, time.time())
        self._odom.put(ODOM.encode(odom))
        self._bumpers.put(BUMPERS.encode({"bumped": result.bumped, "stamp": odom["stamp"]}))
        move = {
            "turned_deg": math.degrees(result.turned_rad),
            "moved_m": result.moved_m,
            "bumped": result.bumped,
            "odom": odom,
        }
        return bus.Reply(MOVE.encode(move))

    def _on_stop(self, _payload: bytes | None) -> bus.Reply:
        self._stops += 1  # a move still waiting for the robot lock will not start
        self.robot.stop()
        return bus.Reply(STOPPED.encode({"stopped": True}))

    def _on_odom(self, _payload: bytes | None) -> bus.Reply:
        with self._lock:
            odometry = self.robot.odometry()
        return bus.Reply(ODOM.encode(odometry_fields(odometry, time.time())))
