"""A robot whose turns in place are measured by its camera (a visual compass), for driving a
recorded route by odometry (:func:`localizer.routes.drive_route`).

Odometry integrates the turns the base was told to make; a wheel that slips on a turn leaves
the heading off by a share of the turn, and every metre driven after it goes off sideways. A
turn in place changes a 360° panorama only by a rotation, so the matched features of the views
before and after the turn give the turn really made (:func:`localizer.visual_homing.
matched_inliers`, to a fraction of a degree; the columns of a 1024-pixel panorama are 0.35°
apart). :class:`CompassedRobot` makes each large turn in place, with a view before and after,
then turns what the turn missed and drives, and reports odometry with the measured turns in
place of the commanded ones. A base whose turns are off by the same share every time (a
wheel base miscalibrated) drove its recorded routes off by that share too: measured turns then
follow the recorded route's shape, not the way the base drove it
(``RouteCheckParams.compass_min_turn_deg`` set to infinity keeps the odometry's turns).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from homing.alv import HomingError
from homing.bearings import wrap_angle_rad
from localizer.robot_protocol import Capture, MoveResult, Pose2D, Robot
from localizer.routes import DriveFrame
from localizer.visual_homing import StepParams, matched_inliers
from mapdb.records import Fingerprint

MAX_TURN_ERROR_DEG = 30.0
"""A turn measured this far (degrees) from the one odometry reports is taken as views that
matched on the wrong rotation, and the odometry's turn is kept: a base does not miss a turn
by as much and still report it made."""


class CompassedRobot:
    """``robot``, its odometry corrected by a visual compass: a move whose turn is at least
    ``min_turn_rad`` (radians) is made as the turn in place with a view before and after
    (``look``: a capture's fingerprint, ``step``: how views are matched), then the drive; the
    turn the views show replaces the odometry's turn (unless the views do not match, or they
    disagree by more than :data:`MAX_TURN_ERROR_DEG`). :meth:`odometry` is in ``robot``'s
    odometry frame as it was when wrapped, and follows moves made on ``robot`` directly too
    (with their turns as the odometry has them)."""

    def __init__(
        self,
        robot: Robot,
        look: Callable[[Capture], Fingerprint],
        step: StepParams,
        min_turn_rad: float,
    ) -> None:
        self.robot, self.look, self.step, self.min_turn_rad = robot, look, step, min_turn_rad
        now = robot.odometry()
        self._frame = DriveFrame(now, now)
        self.corrections_rad: list[float] = []
        """The corrections made so far (measured minus odometric turn, radians)."""
        self.views = 0
        """The views the compass captured so far."""
        self._seen: tuple[Fingerprint, Pose2D] | None = None

    def capture(self) -> Capture:
        return self.robot.capture()

    def stop(self) -> None:
        self.robot.stop()

    def odometry(self) -> Pose2D:
        """The robot's odometry with the measured turns (the frame it had when wrapped)."""
        return self._frame.pose(self.robot.odometry())

    def seen(self, view: Fingerprint) -> None:
        """``view``: the robot's view from where it stands now (a caller took it); the next
        measured turn starts from it if the robot has not moved since, instead of taking one."""
        self._seen = (view, self.robot.odometry())

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        """Turn by ``turn_rad`` and drive ``forward_m`` (as :meth:`Robot.move`); a turn of at
        least ``min_turn_rad`` is measured by the views before and after it, and what it
        missed is turned with the drive, so that the drive goes the way it was told."""
        if not abs(turn_rad) >= self.min_turn_rad:
            self._seen = None
            return self.robot.move(turn_rad, forward_m)
        before = self.robot.odometry()
        seen, self._seen = self._seen, None
        before_view = seen[0] if seen is not None and seen[1] == before else self._view()
        turned = self.robot.move(turn_rad, 0.0)
        error_rad = self._turn_error_rad(before_view, before, self.robot.odometry())
        if forward_m == 0.0:
            return turned
        moved = self.robot.move(-error_rad, forward_m)
        return MoveResult(turned.turned_rad + moved.turned_rad, moved.moved_m, moved.bumped)

    def _turn_error_rad(self, before_view: Fingerprint, before: Pose2D, after: Pose2D) -> float:
        """How much more than the odometry has it (radians, counter-clockwise) the robot turned
        from ``before`` (its odometry then, ``before_view`` its view) to ``after`` (its odometry
        now), by a view taken now; the odometry is corrected by it. 0 if the views do not tell."""
        measured_rad = self._turned_rad(before_view)
        if measured_rad is None:
            return 0.0
        error_rad = float(wrap_angle_rad(measured_rad - (after.heading_rad - before.heading_rad)))
        if abs(error_rad) > math.radians(MAX_TURN_ERROR_DEG):
            return 0.0
        here = self._frame.pose(after)
        self._frame = DriveFrame(Pose2D(here.x_m, here.y_m, here.heading_rad + error_rad), after)
        self.corrections_rad.append(error_rad)
        return error_rad

    def _turned_rad(self, before: Fingerprint) -> float | None:
        """The turn (radians, counter-clockwise) from ``before``'s view to a view taken now,
        by their matched features; None if they do not match."""
        try:
            _, shift_rad = matched_inliers(self._view(), before, self.step)
        except HomingError:
            return None
        return -shift_rad  # a feature at bearing b is seen at b + shift after turning -shift

    def _view(self) -> Fingerprint:
        self.views += 1
        return self.look(self.robot.capture())
