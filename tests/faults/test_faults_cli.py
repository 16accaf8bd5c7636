"""Bad input on the command line gets one line naming it, exit status 1, no traceback (issue 11);
``--debug`` shows the traceback; SIGTERM stops the service quickly and quietly."""

import os
import threading
import time

import cv2
import numpy as np
import pytest
from bus_helpers import free_port, wait_for
from click.testing import CliRunner
from robot_helpers import RobotWrapper

from localizer.robot_protocol import Capture, Pose2D
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.worlds import make_world
from toploc import bus
from toploc.cli import main
from toploc.nodes.localizer import LocalizerClient
from toploc.service import start_service


def run(args: list[str]):
    return CliRunner().invoke(main, args)


def assert_one_line_error(result, *fragments: str) -> None:
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("Error: ")]
    assert len(errors) == 1, result.output
    for fragment in fragments:
        assert fragment in errors[0], result.output


@pytest.fixture
def bad_files(tmp_path):
    """Images nobody should decode: too large for the header check, a FIFO, a non-image."""
    huge = tmp_path / "huge.png"
    cv2.imwrite(str(huge), np.zeros((4000, 20000), np.uint8))  # 80 MP, a few kB of PNG
    fifo = tmp_path / "fifo.png"
    os.mkfifo(fifo)
    text = tmp_path / "notes.png"
    text.write_text("not an image")
    return {"huge": huge, "fifo": fifo, "text": text}


@pytest.mark.parametrize(
    ("name", "fragment"),
    [
        ("huge", "image is 20000x4000 px; at most 75000000 pixels"),
        ("fifo", "not a regular file"),
        ("text", "not an image"),
    ],
)
def test_localize_refuses_a_bad_image_in_one_line(building_map, bad_files, name, fragment):
    image = bad_files[name]
    result = run(["localize", str(image), "--db", str(building_map[0])])
    assert_one_line_error(result, str(image), fragment)


def test_localize_of_dev_zero_ends_at_once(building_map):
    result = run(["localize", "/dev/zero", "--db", str(building_map[0])])
    assert_one_line_error(result, "/dev/zero: not a regular file")


def test_serve_with_a_bad_limits_file_names_it(tmp_path, building_map):
    limits = tmp_path / "limits.toml"
    limits.write_text("max_forward_m = 0\n")
    result = run(["serve", "--db", str(building_map[0]), "--no-sim", "--limits", str(limits)])
    assert_one_line_error(result, str(limits), "max_forward_m must be finite and > 0")


def test_belief_without_a_service_says_so_in_one_line():
    result = run(["belief", "--connect", f"tcp/127.0.0.1:{free_port()}", "--timeout", "0.5"])
    assert_one_line_error(result, "localizer/belief: no reply")


def test_an_unexpected_error_is_one_line_with_a_hint(monkeypatch, building_map):
    def broken(*_args, **_kwargs):
        raise RuntimeError("disk on fire\nsecond line")

    monkeypatch.setattr("toploc.commands.localize.read_panorama", broken)
    result = run(["localize", "any.png", "--db", str(building_map[0])])
    assert_one_line_error(result, "RuntimeError: disk on fire (run with --debug")


def test_debug_shows_the_traceback_of_an_unexpected_error(monkeypatch, building_map):
    def broken(*_args, **_kwargs):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr("toploc.commands.localize.read_panorama", broken)
    result = run(["--debug", "localize", "any.png", "--db", str(building_map[0])])
    assert isinstance(result.exception, RuntimeError)


class SlowCameraRobot(RobotWrapper):
    """The simulated robot in office_b, whose camera takes ``capture_s`` per panorama."""

    def __init__(self, capture_s: float) -> None:
        world = make_world("building")
        pose = world.building_pose("office_b", Pose2D(2.0, 2.5, 0.3))
        super().__init__(SimulatedRobot(world, pose, camera=PanoramaCamera(512, 96), seed=3))
        self.capture_s = capture_s

    def capture(self) -> Capture:
        time.sleep(self.capture_s)
        return self.robot.capture()


def test_stopping_the_service_during_an_active_localization_is_quick(building_map, caplog):
    """What ``serve`` does on SIGTERM. Before: the localization ran to its end (10-15 s at the
    demo's resolution), publishing on undeclared keys."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    service_config = bus.BusConfig(robot_id="stopping", listen=(endpoint,))
    client_config = bus.BusConfig(robot_id="stopping", listen=(), connect=(endpoint,))
    outcome: list[object] = []
    with bus.open_session(client_config) as session:
        client = LocalizerClient(session, "stopping", timeout_s=2.0, localize_timeout_s=120.0)
        states: list[str] = []
        client.subscribe(lambda belief: states.append(belief["state"]))

        def localize() -> None:
            try:
                outcome.append(client.localize(active=True))
            except bus.BusError as error:
                outcome.append(error)

        worker = threading.Thread(target=localize)
        with start_service(building_map[0], service_config, SlowCameraRobot(0.5)):
            assert wait_for(lambda: _answers(client), timeout_s=10.0)
            worker.start()
            assert wait_for(lambda: "homing" in states, timeout_s=60.0), states
            start = time.monotonic()
        stopped_s = time.monotonic() - start
        worker.join(10.0)
    assert stopped_s < 5.0, f"took {stopped_s:.1f} s to stop"  # 2 s is the aim; a loaded CI
    assert not [r for r in caplog.records if "Undeclared" in r.getMessage()]
    assert outcome and isinstance(outcome[0], bus.BusError)  # the client is told, at once
    assert "within 120 s" not in str(outcome[0])


def _answers(client: LocalizerClient) -> bool:
    try:
        client.belief()
    except bus.BusError:
        return False
    return True
