"""Visual homing on the Zenoh bus: :class:`HomingService` drives the service's robot to a stored
place (no Zenoh in it), :class:`HomingNode` serves it,
:class:`~toploc.bus.clients.homing.HomingClient` (also importable from here) talks to it.

Keys under ``toploc/<robot_id>/``:

- ``homing/goal`` (queryable): ``{kind: "goal", place_id, timeout_s?}``; drives by visual homing
  (:func:`localizer.visual_homing.drive_home`, toward the place's stored fingerprint in the
  localizer's map, the views extracted as the localizer does) and replies when the drive ends:
  ``{place_id, arrived, reason, steps, distance_m}`` (kind ``"homing"``). ``reason``: one of
  :class:`~localizer.visual_homing.HomingResult`'s (``arrived``, ``converged``, ``max_steps``,
  ``blocked``: bumped too often, ``lost``: lost the view), or ``cancelled`` (``homing/cancel``)
  or ``timeout`` (``timeout_s`` passed; the base is stopped then). An unknown place, a
  malformed request, one beyond the :class:`~toploc.limits.Limits`, a goal while another goal
  or a localization runs (``busy``: refused at once, not queued: the caller decides whether to
  cancel or wait), or the service stopping: an error reply.
- ``homing/cancel`` (queryable): optional ``{kind: "cancel"}``; cancels the running drive (a bus
  goal, or the drive of an active localization): the base is stopped at once (``base/stop``)
  and the drive ends at its next capture or move. Replies ``{cancelled: bool}`` (false: nothing
  was running).
- ``homing/progress`` (publication): after each capture of a drive ``{place_id, step, features,
  matched, home_length, parallax_deg, moved_m, state}`` (kind ``"progress"``): moves made so
  far (``step``) and odometric metres driven (``moved_m``), the view's features, the matched
  features the home vector used (for ``best``: descriptor matches agreeing on one rotation),
  the home vector's length (ALV units) and the matches' median parallax (degrees; ``best``
  only), ``state`` ``"homing"``, or ``"lost"`` for a view with too few matches (a recovery move
  follows). Both ``home_length`` and ``parallax_deg`` shrink toward the goal and stand for the
  distance to go: there is no estimate in metres, since bearings alone carry no scale (the
  ALV's length depends on the unknown distances to the landmarks). When the drive ends, one
  more message with ``state`` the reply's ``reason``.
- liveliness token ``alive/homing``.

The robot is the one the localizer drives (:attr:`LocalizationRunner.robot`: the service's
:class:`~toploc.nodes.robot.RemoteRobot`, so the robot node's limits and ``base/stop`` apply),
held through :meth:`LocalizationRunner.driving`, so a goal and a localization never drive at
once and the runner's ``stop()`` (SIGTERM) ends a goal at its next capture or move.

The active localizer uses the same code: the service sets ``runner.home`` to
:meth:`HomingService.home`, so its drives publish on ``homing/progress`` and ``homing/cancel``
cancels them (the active localization then looks once where the robot stopped and replies).
That is an in-process call, not a ``homing/goal`` query to its own process: the runner already
holds the robot during an active localization (a query would be refused as busy, or need a way
to say it comes from the holder), and a query would add a timeout to choose and a bus (and an
access control) that the localization's own drive would depend on.

Each drive, a goal's or the active localizer's, ends with one INFO log line: the place, its
room, how the drive ended, the moves made and the odometric metres driven.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeVar

import zenoh

from localizer.robot_protocol import Capture, MoveResult, Pose2D, Robot
from localizer.visual_homing import (
    CANCELLED,
    HomingParams,
    HomingProgress,
    HomingResult,
    drive_home,
)
from mapdb.records import Fingerprint
from toploc import bus
from toploc.bus import schemas
from toploc.bus.clients.homing import GOAL_TIMEOUT_S, HomingClient
from toploc.bus.messages import progress_defaults, progress_message, result_message
from toploc.limits import Limits
from toploc.nodes.node import Node
from toploc.runner import LocalizationRunner

__all__ = [
    "GOAL_TIMEOUT_S",
    "NODE_NAME",
    "TIMEOUT",
    "HomingBusyError",
    "HomingClient",
    "HomingNode",
    "HomingService",
]

T = TypeVar("T")

NODE_NAME = "homing"
TIMEOUT = "timeout"
_log = logging.getLogger(__name__)


class HomingBusyError(RuntimeError):
    """A homing drive is already running."""


class _DriveEnded(Exception):  # noqa: N818 (a signal, not a failure)
    """Raised at a capture or move once the drive was cancelled or timed out."""


@dataclass
class _Drive:
    """One running drive: what it counted so far and why it must end (if it must)."""

    place_id: int
    steps: int = 0
    distance_m: float = 0.0
    lengths: list[float] = field(default_factory=list)
    last_view: Fingerprint | None = None
    last_message: dict[str, Any] = field(default_factory=dict)
    ended: str | None = None  # CANCELLED or TIMEOUT
    lock: threading.Lock = field(default_factory=threading.Lock)

    def end(self, reason: str) -> bool:
        """Mark the drive to end with ``reason``; False if it was already marked."""
        with self.lock:
            if self.ended is not None:
                return False
            self.ended = reason
            return True


class _DriveRobot:
    """``robot`` for one drive: a capture or move raises :class:`_DriveEnded` once the drive was
    told to end, and each move is counted (as ``drive_home`` counts them)."""

    def __init__(self, robot: Robot, drive: _Drive) -> None:
        self.robot = robot
        self.drive = drive

    def _check(self) -> None:
        if self.drive.ended is not None:
            raise _DriveEnded(self.drive.ended)

    def _unless_ended(self, call: Callable[[], T]) -> T:
        """``call()``, first checking that the drive goes on. An error raised after the drive
        was told to end is the end, not an error: the cancel or timeout stops the base, and a
        stop that comes just before a move starts makes the base refuse it ("not moved")."""
        self._check()
        try:
            return call()
        except Exception:
            self._check()
            raise

    def capture(self) -> Capture:
        return self._unless_ended(self.robot.capture)

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        moved = self._unless_ended(lambda: self.robot.move(turn_rad, forward_m))
        self.drive.steps += 1
        self.drive.distance_m += abs(moved.moved_m)
        return moved

    def odometry(self) -> Pose2D:
        return self.robot.odometry()

    def stop(self) -> None:
        self.robot.stop()


class HomingService:
    """Drive ``runner``'s robot to places of ``runner``'s map, one drive at a time, telling
    ``publish`` (e.g. :meth:`HomingNode.publish`; may be set later) of each step."""

    def __init__(
        self,
        runner: LocalizationRunner,
        params: HomingParams | None = None,
        publish: Callable[[dict[str, Any]], object] | None = None,
    ) -> None:
        self.runner = runner
        self.params = params or runner.params.homing
        self.publish = publish
        self._lock = threading.Lock()
        self._drive: _Drive | None = None

    def check_place(self, place_id: int) -> None:
        """``ValueError`` naming ``place_id`` if the localizer's map has no such place."""
        ids = [place.id for place in self.runner.localizer.map.places]
        if place_id not in ids:
            known = f"{min(ids)}..{max(ids)}" if ids else "none"
            raise ValueError(f"unknown place_id {place_id} (the map's places: {known})")

    def goal(self, place_id: int, timeout_s: float | None = None) -> HomingResult:
        """Drive to ``place_id`` (the ``homing/goal`` request); ends with reason ``timeout``
        after ``timeout_s``. :class:`HomingBusyError` or
        :class:`~toploc.runner.RobotBusyError` at once while a drive or a localization runs."""
        self.check_place(place_id)
        with self._lock:
            if self._drive is not None:
                raise HomingBusyError(
                    f"busy: homing to place {self._drive.place_id}; cancel it (homing/cancel) "
                    "or try again when it has ended"
                )
        with self.runner.driving():
            return self._run(place_id, timeout_s)

    def home(self, place_id: int) -> HomingResult:
        """Drive to ``place_id`` for the active localizer (``runner.home``): the runner holds
        the robot already."""
        return self._run(place_id, None)

    def cancel(self) -> bool:
        """End the running drive (the base is stopped now, the drive ends at its next capture
        or move); whether one was running."""
        with self._lock:
            drive = self._drive
        if drive is None or not drive.end(CANCELLED):
            return False
        self._stop_base()
        return True

    def running(self) -> int | None:
        """The place the running drive goes to, or None."""
        with self._lock:
            return None if self._drive is None else self._drive.place_id

    def _stop_base(self) -> None:
        try:
            self.runner.robot.stop()
        except Exception as error:  # the drive ends at its next step whatever the base says
            _log.warning("could not stop the robot: %s", error)

    def _publish(self, message: dict[str, Any]) -> None:
        if self.publish is not None:
            self.publish(message)

    def _on_step(self, drive: _Drive, progress: HomingProgress) -> None:
        drive.last_view = progress.view
        if progress.home is not None:
            drive.lengths.append(progress.home.length)
        drive.last_message = progress_message(drive.place_id, progress)
        self._publish(drive.last_message)

    def _expire(self, drive: _Drive) -> None:
        if drive.end(TIMEOUT):
            self._stop_base()

    def _run(self, place_id: int, timeout_s: float | None) -> HomingResult:
        drive = _Drive(place_id)
        with self._lock:
            if self._drive is not None:
                raise HomingBusyError(f"busy: homing to place {self._drive.place_id}")
            self._drive = drive
        timer = None
        if timeout_s is not None:
            timer = threading.Timer(timeout_s, self._expire, (drive,))
            timer.daemon = True
            timer.start()
        try:
            localizer = self.runner.localizer
            goal = localizer.map.fingerprint(place_id)
            robot = _DriveRobot(self.runner.robot, drive)
            try:
                result = drive_home(
                    robot,
                    goal,
                    localizer.extract,
                    self.params,
                    on_step=lambda progress: self._on_step(drive, progress),
                )
            except _DriveEnded as ended:
                last = drive.last_view or Fingerprint.empty(
                    goal.detector, goal.image_width_px, goal.image_height_px
                )
                result = HomingResult(
                    False, drive.steps, drive.distance_m, str(ended), last, tuple(drive.lengths)
                )
            end = {"step": result.steps, "moved_m": result.distance_m, "state": result.reason}
            self._publish({**progress_defaults(place_id), **drive.last_message, **end})
            _log.info(
                "homing to place %d (%s): %s after %d moves, %.2f m",
                place_id,
                localizer.map.place(place_id).room,
                result.reason,
                result.steps,
                result.distance_m,
            )
            return result
        finally:
            if timer is not None:
                timer.cancel()
            with self._lock:
                self._drive = None


class HomingNode(Node):
    """Serve ``service`` on the bus under ``toploc/<robot_id>/`` within ``limits``; ``close()``
    (or ``with``)."""

    def __init__(
        self,
        session: zenoh.Session,
        robot_id: str,
        service: HomingService,
        limits: Limits | None = None,
    ) -> None:
        super().__init__(session, robot_id, NODE_NAME)
        self.service = service
        self.limits = limits or Limits()
        self._publisher = session.declare_publisher(self.key(bus.HOMING_PROGRESS))
        self.entities += [
            bus.serve(session, self.key(bus.HOMING_GOAL), self._on_goal, threaded=True),
            bus.serve(session, self.key(bus.HOMING_CANCEL), self._on_cancel),
            self._publisher,
            session.liveliness().declare_token(bus.alive_key(robot_id, NODE_NAME)),
        ]

    def publish(self, progress: dict[str, Any]) -> None:
        """Publish one ``homing/progress`` message (a failure is logged: the drive goes on)."""
        try:
            self._publisher.put(schemas.PROGRESS.encode(progress))
        except (ValueError, zenoh.ZError) as error:
            _log.warning("could not publish homing progress: %s", error)

    def _decode(self, suffix: str, payload: bytes | None, kind: str) -> dict[str, Any]:
        limits = self.limits
        return bus.decode(
            self.key(suffix), payload, None, kind, limits.max_request_bytes, limits.max_string_chars
        )

    def _on_goal(self, payload: bytes | None) -> bus.Reply:
        where = self.key(bus.HOMING_GOAL)
        request = self._decode(bus.HOMING_GOAL, payload, schemas.GOAL.kind)
        bus.check_fields(where, request, schemas.GOAL.fields)
        timeout_s = request.get("timeout_s")
        if timeout_s is not None and (not bus.has_type(timeout_s, float) or timeout_s <= 0):
            raise bus.BusMessageError(f"{where}: timeout_s must be a number > 0, got {timeout_s!r}")
        place_id = request["place_id"]
        try:
            result = self.service.goal(place_id, timeout_s)
        except ValueError as error:
            raise bus.BusMessageError(f"{where}: {error}") from None
        return bus.Reply(schemas.HOMING_RESULT.encode(result_message(place_id, result)))

    def _on_cancel(self, payload: bytes | None) -> bus.Reply:
        if payload:
            self._decode(bus.HOMING_CANCEL, payload, schemas.CANCEL.kind)
        return bus.Reply(schemas.CANCELLED.encode({"cancelled": self.service.cancel()}))
