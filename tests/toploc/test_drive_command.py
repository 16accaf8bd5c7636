"""``toploc drive`` against a robot node on a real Zenoh bus (127.0.0.1, a free port per test)."""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator

import numpy as np
import pytest
from bus_helpers import ROBOT_ID, Bus, free_endpoint
from click.testing import CliRunner, Result

from localizer.robot_protocol import Capture, MoveResult, Pose2D
from toploc.cli import main
from toploc.limits import Limits
from toploc.nodes.robot import RobotNode


class WalledRobot:
    """A base on a line with a wall ``wall_m`` ahead; ``hold`` makes each move wait until it is
    set (by :meth:`stop` too), as a base still driving does."""

    def __init__(self, wall_m: float = 1.0) -> None:
        self.wall_m = wall_m
        self.x_m, self.heading_rad = 0.0, 0.0
        self.moves: list[tuple[float, float]] = []
        self.stops = 0
        self.hold: threading.Event | None = None
        self.moving = threading.Event()

    def capture(self) -> Capture:
        return Capture(np.zeros((8, 32), np.uint8), stamp_s=1.0, source="none")

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        self.moving.set()
        if self.hold is not None:
            self.hold.wait(10)
        self.moves.append((turn_rad, forward_m))
        moved_m = min(forward_m, self.wall_m - self.x_m)
        self.heading_rad += turn_rad
        self.x_m += moved_m
        return MoveResult(turn_rad, moved_m, bumped=moved_m < forward_m)

    def odometry(self) -> Pose2D:
        return Pose2D(self.x_m, 0.0, self.heading_rad)

    def stop(self) -> None:
        self.stops += 1
        if self.hold is not None:
            self.hold.set()


@pytest.fixture
def base(zbus: Bus) -> Iterator[tuple[Bus, WalledRobot]]:
    robot = WalledRobot()
    with RobotNode(zbus.server, ROBOT_ID, robot, Limits(max_forward_m=2.0)):
        zbus.wait_alive("robot")
        yield zbus, robot


def drive(endpoint: str, *args: str) -> Result:
    bus_args = ["--robot-id", ROBOT_ID, "--connect", endpoint]
    return CliRunner().invoke(main, ["drive", *bus_args, *args])


def error_line(done: Result) -> str:
    """The one ``Error:`` line on stderr (the node, in this process, logs on stderr too)."""
    errors = [line for line in done.stderr.splitlines() if line.startswith("Error:")]
    assert len(errors) == 1, done.output
    return errors[0]


def test_drive_turns_then_moves_and_prints_what_the_base_did(base):
    zbus, robot = base
    done = drive(zbus.endpoint, "--turn-deg", "90", "--forward-m", "0.5")
    assert done.exit_code == 0, done.output
    assert robot.moves == [(pytest.approx(math.pi / 2), 0.5)]
    assert done.stdout == (
        "turned 90.0 deg, moved 0.50 m, no bump; odometry x 0.50 m, y 0.00 m, heading 90.0 deg\n"
    )


def test_a_turn_alone_drives_nowhere(base):
    zbus, robot = base
    done = drive(zbus.endpoint, "--turn-deg", "-30")
    assert done.exit_code == 0, done.output
    assert robot.moves == [(pytest.approx(math.radians(-30)), 0.0)]


def test_a_bump_prints_the_move_and_fails(base):
    zbus, _ = base
    done = drive(zbus.endpoint, "--forward-m", "1.5")
    assert done.exit_code == 1
    assert done.stdout == (
        "turned 0.0 deg, moved 1.00 m, bumped; odometry x 1.00 m, y 0.00 m, heading 0.0 deg\n"
    )
    assert error_line(done) == "Error: the base bumped into something: moved 1.00 m of 1.50 m"


def test_a_move_beyond_the_limits_is_refused_in_one_line_and_not_made(base):
    zbus, robot = base
    done = drive(zbus.endpoint, "--forward-m", "3")
    assert done.exit_code == 1
    assert robot.moves == []
    assert error_line(done) == (
        f"Error: toploc/{ROBOT_ID}/base/cmd: forward_m 3.0 is beyond the limit of 2 m per command"
    )


def test_stop_stops_the_base(base):
    zbus, robot = base
    done = drive(zbus.endpoint, "--stop")
    assert (done.exit_code, done.stdout) == (0, "stopped\n")
    assert robot.stops == 1 and robot.moves == []


def test_a_drive_that_gives_up_waiting_stops_the_base(base):
    zbus, robot = base
    robot.hold = threading.Event()  # released by the stop the command sends
    done = drive(zbus.endpoint, "--forward-m", "0.5", "--timeout", "0.5")
    assert done.exit_code == 1
    error = error_line(done)
    assert error.startswith(f"Error: toploc/{ROBOT_ID}/base/cmd: no reply within 0.5 s")
    assert error.endswith("; sent base/stop")
    assert robot.stops == 1


def test_a_move_the_service_times_out_is_an_error(zbus):
    robot = WalledRobot()
    robot.hold = threading.Event()
    with RobotNode(zbus.server, ROBOT_ID, robot, Limits(move_timeout_s=0.3)):
        zbus.wait_alive("robot")
        done = drive(zbus.endpoint, "--forward-m", "0.5")
    assert done.exit_code == 1
    assert error_line(done).endswith("the move did not finish within 0.3 s; the base was stopped")
    assert robot.stops >= 1


def test_drive_without_a_service_fails_clearly():
    done = drive(free_endpoint(), "--forward-m", "0.5", "--timeout", "0.3")
    assert done.exit_code == 1
    assert error_line(done).startswith(f"Error: toploc/{ROBOT_ID}/base/cmd: no reply")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ((), "give --turn-deg and/or --forward-m (or --stop)"),
        (("--stop", "--forward-m", "1"), "--stop stops the base"),
        (("--forward-m", "nan"), "must be a finite number"),
    ],
)
def test_drive_refuses_what_it_cannot_send(args, message):
    done = drive(free_endpoint(), *args)
    assert done.exit_code == 2
    assert message in done.output
