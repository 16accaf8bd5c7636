"""A robot for the tests that passes every call to a real one, so a test overrides only what it
gates or slows (a capture that waits for the test, a camera that takes its time)."""

from localizer.robot_protocol import Capture, MoveResult, Pose2D, Robot


class RobotWrapper:
    """A :class:`~localizer.robot_protocol.Robot` that passes every call to ``robot``."""

    def __init__(self, robot: Robot) -> None:
        self.robot = robot

    def capture(self) -> Capture:
        return self.robot.capture()

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        return self.robot.move(turn_rad, forward_m)

    def odometry(self) -> Pose2D:
        return self.robot.odometry()

    def stop(self) -> None:
        self.robot.stop()
