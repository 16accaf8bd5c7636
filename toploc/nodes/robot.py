"""The robot on the Zenoh bus: :class:`RobotNode` serves a :class:`~localizer.robot_protocol.Robot`
(and, if given, a separate :class:`~localizer.robot_protocol.Camera` for its captures),
:class:`RemoteRobot` is a Robot that talks to such a node.

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

import cv2
import numpy as np
import zenoh

from localizer.panorama_io import (
    MAX_IMAGE_PIXELS,
    ImageTooLargeError,
    PanoramaError,
    check_image_header,
)
from localizer.robot_protocol import Camera, Capture, MoveResult, Pose2D, Robot
from toploc import bus
from toploc.limits import Limits
from toploc.nodes.camera import CameraNode
from toploc.nodes.node import Client, Node

NODE_NAME = "robot"
CMD_FIELDS: dict[str, bus.FieldType] = {"turn_deg": float, "forward_m": float}
MOVE_FIELDS: dict[str, bus.FieldType] = {
    "turned_deg": float,
    "moved_m": float,
    "bumped": bool,
    "odom": dict,
}
ODOM_FIELDS: dict[str, bus.FieldType] = {
    "x_m": float,
    "y_m": float,
    "heading_deg": float,
    "stamp": float,
}
CAPTURE_FIELDS: dict[str, bus.FieldType] = {
    "capture_id": int,
    "stamp": float,
    "heading_deg": float,
    "source": str,
}


def odometry_fields(odometry: Pose2D, stamp_s: float) -> dict[str, float]:
    """The ``base/odom`` fields of ``odometry`` (heading in degrees, stamp in seconds)."""
    return {
        "x_m": odometry.x_m,
        "y_m": odometry.y_m,
        "heading_deg": math.degrees(odometry.heading_rad),
        "stamp": stamp_s,
    }


def odometry_from_fields(message: dict[str, Any]) -> Pose2D:
    """Inverse of :func:`odometry_fields` (on a checked message)."""
    return Pose2D(message["x_m"], message["y_m"], math.radians(message["heading_deg"]))


def decode_png(key_expr: str, data: bytes, max_pixels: int = MAX_IMAGE_PIXELS) -> np.ndarray:
    """The image in PNG ``data`` received on ``key_expr``; BusMessageError if it is not one, or
    (read from its header, before decoding) has more than ``max_pixels`` pixels."""
    not_an_image = bus.BusMessageError(
        f"{key_expr}: reply is not a decodable image ({len(data)} bytes, starts {data[:8]!r})"
    )
    try:
        check_image_header(data, key_expr, max_pixels)
    except ImageTooLargeError as error:
        raise bus.BusMessageError(str(error)) from None
    except PanoramaError:
        raise not_an_image from None
    try:
        image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error:
        image = None
    if image is None:
        raise not_an_image
    return image


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
        command = bus.decode(
            where, payload, CMD_FIELDS, "cmd", limits.max_request_bytes, limits.max_string_chars
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
        self._odom.put(bus.encode("odom", odom))
        self._bumpers.put(bus.encode("bumpers", {"bumped": result.bumped, "stamp": odom["stamp"]}))
        move = {
            "turned_deg": math.degrees(result.turned_rad),
            "moved_m": result.moved_m,
            "bumped": result.bumped,
            "odom": odom,
        }
        return bus.Reply(bus.encode("move", move))

    def _on_stop(self, _payload: bytes | None) -> bus.Reply:
        self._stops += 1  # a move still waiting for the robot lock will not start
        self.robot.stop()
        return bus.Reply(bus.encode("stopped", {"stopped": True}))

    def _on_odom(self, _payload: bytes | None) -> bus.Reply:
        with self._lock:
            odometry = self.robot.odometry()
        return bus.Reply(bus.encode("odom", odometry_fields(odometry, time.time())))


class RemoteRobot(Client):
    """A :class:`~localizer.robot_protocol.Robot` whose calls go over the bus to a
    :class:`RobotNode`.

    ``timeout_s`` bounds capture and odometry queries, ``move_timeout_s`` a move (it replies
    when done), ``max_image_pixels`` a captured image (checked in its header). Every call
    raises :class:`~toploc.bus.BusTimeout` if the node does not answer,
    :class:`~toploc.bus.BusReplyError` for an error reply, :class:`~toploc.bus.BusMessageError`
    for a reply that breaks the contract (e.g. a corrupt or oversized image). It listens to
    ``base/odom`` until :meth:`close`.
    """

    def __init__(
        self,
        session: zenoh.Session,
        robot_id: str,
        timeout_s: float = bus.DEFAULT_TIMEOUT_S,
        move_timeout_s: float = 60.0,
        max_image_pixels: int = MAX_IMAGE_PIXELS,
    ) -> None:
        super().__init__(session, robot_id, timeout_s)
        self.move_timeout_s = move_timeout_s
        self.max_image_pixels = max_image_pixels
        self.last_capture_meta: dict[str, Any] | None = None
        self._odom_lock = threading.Lock()
        self._last_odom: tuple[float, Pose2D] | None = None  # (stamp_s, odometry)
        self._subscribe(  # odometry() falls back to a query without one
            bus.BASE_ODOM,
            lambda key_expr, data: bus.decode(key_expr, data, ODOM_FIELDS),
            self._remember,
        )

    def _remember(self, odom: dict[str, Any]) -> Pose2D:
        """Keep the newest odometry by stamp (publications arrive on another thread)."""
        odometry = odometry_from_fields(odom)
        with self._odom_lock:
            if self._last_odom is None or odom["stamp"] >= self._last_odom[0]:
                self._last_odom = (odom["stamp"], odometry)
        return odometry

    def capture(self) -> Capture:
        """Query ``camera/capture``; the attachment is kept in :attr:`last_capture_meta`.

        A capture refused by the camera's rate limit (an error reply with ``retry_after_s``) is
        asked again after that wait, as long as the wait ends within ``timeout_s`` of the first
        ask: the node's own localizer or homing must not fail because another client was
        capturing too (or because a fast query path outran the limit)."""
        key_expr = bus.key(self.robot_id, bus.CAMERA_CAPTURE)
        deadline_s = time.monotonic() + self.timeout_s
        timeout_s = self.timeout_s
        while True:
            try:
                sample = bus.request(self.session, key_expr, None, timeout_s)
                break
            except bus.BusReplyError as error:
                wait_s = None if error.retry_after_s is None else max(error.retry_after_s, 0.01)
                if wait_s is None or time.monotonic() + wait_s >= deadline_s:
                    raise
                time.sleep(wait_s)
                timeout_s = max(deadline_s - time.monotonic(), 0.01)
        if sample.attachment is None:
            raise bus.BusMessageError(f"{key_expr}: reply has no capture attachment")
        meta = bus.decode(f"{key_expr} (attachment)", sample.attachment.to_bytes(), CAPTURE_FIELDS)
        image = decode_png(key_expr, sample.payload.to_bytes(), self.max_image_pixels)
        self.last_capture_meta = meta
        return Capture(image=image, stamp_s=float(meta["stamp"]), source=meta["source"])

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        """Query ``base/cmd`` and wait (up to ``move_timeout_s``) for the move to finish."""
        key_expr = bus.key(self.robot_id, bus.BASE_CMD)
        command = bus.encode("cmd", {"turn_deg": math.degrees(turn_rad), "forward_m": forward_m})
        reply = bus.request_json(self.session, key_expr, MOVE_FIELDS, command, self.move_timeout_s)
        bus.check_fields(f"{key_expr} (odom)", reply["odom"], ODOM_FIELDS)
        self._remember(reply["odom"])
        return MoveResult(math.radians(reply["turned_deg"]), reply["moved_m"], reply["bumped"])

    def stop(self) -> None:
        """Query ``base/stop``: the node stops the base at once, also during a move."""
        key_expr = bus.key(self.robot_id, bus.BASE_STOP)
        bus.request(self.session, key_expr, bus.encode("stop", {}), self.timeout_s)

    def odometry(self) -> Pose2D:
        """The newest odometry seen (``base/odom`` publications and move replies), or a
        ``base/odom`` query if none arrived yet."""
        with self._odom_lock:
            if self._last_odom is not None:
                return self._last_odom[1]
        key_expr = bus.key(self.robot_id, bus.BASE_ODOM)
        message = bus.request_json(self.session, key_expr, ODOM_FIELDS, None, self.timeout_s)
        return self._remember(message)
