"""A camera on the Zenoh bus: :class:`CameraNode` serves ``camera/capture`` (and publishes
``camera/panorama``) from a :class:`~localizer.robot_protocol.Camera`.

It is the one implementation of the capture keys: a :class:`~toploc.nodes.robot.RobotNode`
composes one (its camera, the base's heading, the base's lock), and ``toploc node camera`` runs
one alone, for a camera without a base (its heading is then the newest ``base/odom`` of the
bus's robot node, 0 when none answers).

Keys under ``toploc/<robot_id>/``:

- ``camera/capture`` (queryable, at most ``max_captures_per_s``): capture now; reply PNG bytes
  with the JSON attachment ``{schema, kind: "capture", capture_id, stamp, heading_deg,
  source}`` (:data:`toploc.bus.schemas.CAPTURE`); the same sample is published on
  ``camera/panorama``. ``heading_deg`` is the odometry heading at capture time.
- liveliness token ``alive/camera`` (also while a robot node serves its camera): one node per
  robot id serves the capture keys; a second one, or a robot node that would serve its camera
  while a camera node runs, refuses to start (run that robot node with ``--no-camera``).
"""

from __future__ import annotations

import contextlib
import itertools
import math
import threading
from collections.abc import Callable

import zenoh

from localizer.robot_protocol import Camera
from toploc import bus
from toploc.bus.clients.robot import RemoteRobot
from toploc.bus.png_codec import encode_png
from toploc.bus.schemas import CAPTURE
from toploc.limits import Limits, RateLimit
from toploc.nodes.node import Node

NODE_NAME = "camera"
BUS_HEADING_TIMEOUT_S = 0.5
"""How long a camera node alone waits for the robot node's ``base/odom`` per capture."""


class CameraNode(Node):
    """Serve ``camera`` on the bus under ``toploc/<robot_id>/`` within ``limits``; ``close()``
    (or ``with``). ``heading_deg``: the odometry heading at capture time (default: the bus's
    robot node's, see :func:`bus_heading`); ``lock``: held around a capture and its heading
    (a robot node's, so a move waits for the capture)."""

    def __init__(
        self,
        session: zenoh.Session,
        robot_id: str,
        camera: Camera,
        limits: Limits | None = None,
        heading_deg: Callable[[], float] | None = None,
        lock: threading.Lock | None = None,
    ) -> None:
        super().__init__(session, robot_id, NODE_NAME)
        self.camera = camera
        self.limits = limits or Limits()
        self._remote: RemoteRobot | None = None
        if heading_deg is None:
            heading_deg = self._bus_heading
        self.heading_deg = heading_deg
        self._lock = lock or threading.Lock()
        self._captures = RateLimit(self.limits.max_captures_per_s)
        self._capture_ids = itertools.count(1)
        self._panorama = session.declare_publisher(bus.key(robot_id, bus.CAMERA_PANORAMA))
        self.entities += [
            bus.serve(session, bus.key(robot_id, bus.CAMERA_CAPTURE), self._on_capture),
            self._panorama,
            session.liveliness().declare_token(bus.alive_key(robot_id, NODE_NAME)),
        ]

    def close(self) -> None:
        """Undeclare everything (the session stays open; the camera is the caller's)."""
        super().close()
        if self._remote is not None:
            self._remote.close()

    def _bus_heading(self) -> float:
        """The newest heading of the bus's robot node (``base/odom``), 0 if none answers."""
        if self._remote is None:
            self._remote = RemoteRobot(self.session, self.robot_id, BUS_HEADING_TIMEOUT_S)
        with contextlib.suppress(bus.BusError):
            return math.degrees(self._remote.odometry().heading_rad)
        return 0.0

    def _on_capture(self, _payload: bytes | None) -> bus.Reply:
        if not self._captures.allow():
            raise bus.BusRateLimited(
                f"rate limited: at most {self.limits.max_captures_per_s} captures per second",
                self._captures.wait_s(),
            )
        with self._lock:
            capture = self.camera.capture()
            heading_deg = self.heading_deg()
        meta = {
            "capture_id": next(self._capture_ids),
            "stamp": capture.stamp_s,
            "heading_deg": heading_deg,
            "source": capture.source,
        }
        reply = bus.Reply(encode_png(capture.image), CAPTURE.encode(meta))
        self._panorama.put(reply.payload, attachment=reply.attachment)
        return reply
