"""A :class:`~localizer.robot_protocol.Robot` on the far side of the bus: :class:`RemoteRobot`
talks to a :class:`~toploc.nodes.robot.RobotNode` (the base keys) and to whichever node serves
``camera/capture`` (the robot node's own camera, or a :class:`~toploc.nodes.camera.CameraNode`)."""

from __future__ import annotations

import math
import threading
import time
from typing import Any

import zenoh

from localizer.panorama_io import MAX_IMAGE_PIXELS
from localizer.robot_protocol import Capture, MoveResult, Pose2D
from toploc import bus
from toploc.bus.clients.base import Client
from toploc.bus.messages import odometry_from_fields
from toploc.bus.png_codec import decode_png
from toploc.bus.schemas import CAPTURE, CMD, MOVE, ODOM, STOP


class RemoteRobot(Client):
    """A :class:`~localizer.robot_protocol.Robot` whose calls go over the bus to a
    :class:`~toploc.nodes.robot.RobotNode`.

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
            lambda key_expr, data: ODOM.decode(key_expr, data, check_kind=False),
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
        meta = CAPTURE.decode(f"{key_expr} (attachment)", sample.attachment.to_bytes(), False)
        image = decode_png(key_expr, sample.payload.to_bytes(), self.max_image_pixels)
        self.last_capture_meta = meta
        return Capture(image=image, stamp_s=float(meta["stamp"]), source=meta["source"])

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        """Query ``base/cmd`` and wait (up to ``move_timeout_s``) for the move to finish."""
        key_expr = bus.key(self.robot_id, bus.BASE_CMD)
        command = CMD.encode({"turn_deg": math.degrees(turn_rad), "forward_m": forward_m})
        reply = bus.request_json(self.session, key_expr, MOVE.fields, command, self.move_timeout_s)
        bus.check_fields(f"{key_expr} (odom)", reply["odom"], ODOM.fields)
        self._remember(reply["odom"])
        return MoveResult(math.radians(reply["turned_deg"]), reply["moved_m"], reply["bumped"])

    def stop(self) -> None:
        """Query ``base/stop``: the node stops the base at once, also during a move."""
        key_expr = bus.key(self.robot_id, bus.BASE_STOP)
        bus.request(self.session, key_expr, STOP.encode({}), self.timeout_s)

    def odometry(self) -> Pose2D:
        """The newest odometry seen (``base/odom`` publications and move replies), or a
        ``base/odom`` query if none arrived yet."""
        with self._odom_lock:
            if self._last_odom is not None:
                return self._last_odom[1]
        key_expr = bus.key(self.robot_id, bus.BASE_ODOM)
        message = bus.request_json(self.session, key_expr, ODOM.fields, None, self.timeout_s)
        return self._remember(message)
