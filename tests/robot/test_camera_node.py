"""A camera source on the bus: the robot node serves ``camera/capture`` (and publishes
``camera/panorama``) from the camera it is given, the base stays the robot's; ``serve
--source`` fails in one line before any map is made."""

from __future__ import annotations

import math
import threading
from pathlib import Path

import cv2
import numpy as np
import zenoh
from bus_helpers import ROBOT_ID, Bus, wait_for
from click.testing import CliRunner

from localizer.robot_protocol import Capture, MoveResult, Pose2D
from robot.camera_sources import open_source
from toploc import bus
from toploc.bus.png_codec import decode_png
from toploc.cli import main
from toploc.nodes.robot import RemoteRobot, RobotNode


class Base:
    """A base without a camera of its own: capturing from it is a mistake."""

    def capture(self) -> Capture:
        raise AssertionError("the base's capture must not be used when a camera is given")

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        return MoveResult(turn_rad, forward_m, False)

    def odometry(self) -> Pose2D:
        return Pose2D(0.0, 0.0, math.radians(30.0))

    def stop(self) -> None:
        """Nothing moves."""


def test_robot_node_serves_the_camera_it_is_given(zbus: Bus, tmp_path: Path) -> None:
    images = {}
    for i, name in enumerate(["a.png", "b.png"]):
        images[name] = np.random.default_rng(i).integers(0, 256, (24, 96), np.uint8)
        cv2.imwrite(str(tmp_path / name), images[name])
    camera = open_source(f"files:{tmp_path}")
    published: list[bytes] = []
    got = threading.Event()

    def on_panorama(sample: zenoh.Sample) -> None:
        published.append(sample.payload.to_bytes())
        got.set()

    subscriber = zbus.client.declare_subscriber(
        bus.key(ROBOT_ID, bus.CAMERA_PANORAMA), zenoh.handlers.Callback(on_panorama)
    )
    with RobotNode(zbus.server, ROBOT_ID, Base(), camera=camera):
        zbus.wait_alive("robot")
        remote = RemoteRobot(zbus.client, ROBOT_ID, timeout_s=2.0)
        first, second = remote.capture(), remote.capture()
        assert first.source == "files:a.png" and second.source == "files:b.png"
        np.testing.assert_array_equal(first.image, images["a.png"])
        np.testing.assert_array_equal(second.image, images["b.png"])
        assert remote.last_capture_meta is not None
        assert abs(remote.last_capture_meta["heading_deg"] - 30.0) < 1e-9  # the base odometry
        assert wait_for(lambda: len(published) >= 2)
        np.testing.assert_array_equal(decode_png("pub", published[0]), images["a.png"])
        remote.close()
    subscriber.undeclare()


def test_a_failing_camera_is_an_error_reply_naming_it(zbus: Bus, tmp_path: Path) -> None:
    (tmp_path / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 20)
    with RobotNode(zbus.server, ROBOT_ID, Base(), camera=open_source(f"files:{tmp_path}")):
        zbus.wait_alive("robot")
        remote = RemoteRobot(zbus.client, ROBOT_ID, timeout_s=2.0)
        try:
            remote.capture()
        except bus.BusReplyError as error:
            assert "broken.png" in str(error)
        else:
            raise AssertionError("a corrupt image was served")
        remote.close()


def run_serve(*args: str) -> list[str]:
    result = CliRunner().invoke(main, ["serve", *args])
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    return [line for line in result.output.splitlines() if line.startswith("Error: ")]


def test_serve_refuses_a_bad_source_in_one_line_before_making_a_map(tmp_path: Path) -> None:
    db = tmp_path / "never-read.db"
    db.write_bytes(b"")
    errors = run_serve("--db", str(db), "--source", "webcam:0")
    assert len(errors) == 1 and "webcam:0" in errors[0] and "unknown kind" in errors[0]
    errors = run_serve("--db", str(db), "--source", f"files:{tmp_path / 'none'}")
    assert len(errors) == 1 and "is not a folder" in errors[0]
    errors = run_serve("--db", str(db), "--no-sim", "--source", f"files:{tmp_path}")
    assert len(errors) == 1 and "--no-sim" in errors[0]
