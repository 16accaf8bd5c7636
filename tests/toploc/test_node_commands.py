"""``toploc node robot|camera|localizer|map``: each node in a process of its own, joined only by
Zenoh on 127.0.0.1 (the map node listens, the others connect), as a user runs them; and
``toploc serve`` (all of them in one process) on a new map, stopped by either signal."""

from __future__ import annotations

import os
import queue
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import cv2
import numpy as np
import pytest
from bus_helpers import free_port

from toploc import bus
from toploc.bus.png_codec import encode_png
from toploc.nodes.localizer import LocalizerClient
from toploc.nodes.mapdb import MapClient
from toploc.nodes.robot import RemoteRobot, RobotNode

REPO = Path(__file__).resolve().parents[2]
READY = "Ctrl-C stops."


class Node:
    """A ``python -m toploc node ...`` (``command``: another toploc command) process; its output
    lines on a queue."""

    def __init__(self, *args: str, command: tuple[str, ...] = ("node",)) -> None:
        self.args = args
        env = {
            **os.environ,
            "PYTHONPATH": str(REPO),
            "PYTHONUNBUFFERED": "1",
        }
        self.process = subprocess.Popen(
            [sys.executable, "-m", "toploc", *command, *args],
            cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
        self.lines: queue.Queue[str] = queue.Queue()
        self.output: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            self.output.append(line.rstrip())
            self.lines.put(line.rstrip())

    def wait_ready(self, timeout_s: float = 20.0) -> str:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                line = self.lines.get(timeout=0.1)
            except queue.Empty:
                assert self.process.poll() is None, f"node exited: {self.output}"
                continue
            if READY in line:
                return line
        raise AssertionError(f"node not ready after {timeout_s} s: {self.output}")

    def stop(self, timeout_s: float = 20.0) -> int:
        """SIGTERM, as a service manager stops it; the exit status. A node still running after
        ``timeout_s`` is asked for its threads' stacks (``SIGUSR1``), then killed."""
        if self.process.poll() is None:
            self.process.terminate()
        try:
            return self.process.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self.process.send_signal(signal.SIGUSR1)
            time.sleep(2.0)  # the stacks reach the output
            self.process.kill()
            return self.process.wait()


@contextmanager
def nodes(*commands: tuple[str, ...]) -> Iterator[list[Node]]:
    """Start each node in turn (each ready before the next), stop them all at the end; if the
    block failed, print every node's output (pytest shows it with the failure)."""
    started: list[Node] = []
    failed = True
    try:
        for command in commands:
            started.append(Node(*command))
            started[-1].wait_ready()
        yield started
        failed = False
    finally:
        for node in reversed(started):
            node.stop()
        for node in started if failed else ():
            print(f"--- toploc node {node.args[0]} (exit {node.process.returncode}) ---")
            print("\n".join(node.output))


def diagnosis(belief: dict, running: list[Node]) -> str:
    """What a failed wait shows: the last belief, then each node's output with its threads'
    stacks (``SIGUSR1``) at that moment."""
    for node in running:
        if node.process.poll() is None:
            node.process.send_signal(signal.SIGUSR1)
    time.sleep(2.0)  # the stacks reach the output
    return "\n\n".join([str(belief), *("\n".join(node.output) for node in running)])


def client_session(endpoint: str, robot_id: str):
    return bus.open_session(bus.BusConfig(robot_id, listen=(), connect=(endpoint,)))


def test_robot_map_and_localizer_nodes_in_three_processes(building_map, tmp_path: Path) -> None:
    db = tmp_path / "map.db"
    shutil.copy(building_map[0], db)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    ids = ("--robot-id", "n3")
    joined = ("--connect", endpoint, *ids)
    with (
        nodes(
            ("map", "--db", str(db), "--listen", endpoint, *ids),
            ("robot", "--robot", "sim", "--sim-room", "office_b", "--db", str(db), *joined),
            ("localizer", "--db", str(db), *joined),
        ) as running,
        client_session(endpoint, "n3") as session,
    ):
        assert "building/office_b" in running[1].output[-1]
        assert running[1].output[0].startswith("robot id: n3")
        localizer = LocalizerClient(session, "n3", timeout_s=10, localize_timeout_s=60)
        belief = localizer.localize()
        assert belief["top"]["room"] == "office_b", belief["rooms"]

        remote = RemoteRobot(session, "n3", timeout_s=10)
        added = MapClient(session, "n3").add(encode_png(remote.capture().image), "annex")
        remote.close()
        deadline = time.monotonic() + 25.0
        while time.monotonic() < deadline:  # refreshed 2 s after map/changed
            belief = localizer.localize()
            if belief["best_place"]["place_id"] == added["place_id"]:
                break
            time.sleep(0.5)
        assert belief["best_place"]["place_id"] == added["place_id"], diagnosis(belief, running)
        assert "annex" in belief["rooms"]
    codes = [node.process.returncode for node in running]
    assert codes == [0, 0, 0], "\n\n".join("\n".join(node.output) for node in running)
    assert all(node.output[-1] == "stopped" for node in running)


def test_a_camera_node_serves_captures_without_a_base(tmp_path: Path) -> None:
    images = {}
    for i, name in enumerate(["a.png", "b.png"]):
        images[name] = np.random.default_rng(i).integers(0, 256, (24, 96), np.uint8)
        cv2.imwrite(str(tmp_path / name), images[name])
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with (
        nodes(("camera", "--source", f"files:{tmp_path}", "--listen", endpoint, "--robot-id", "c1")),  # noqa: E501
        client_session(endpoint, "c1") as session,
        ExitStack() as stack,
    ):  # fmt: skip
        remote = RemoteRobot(session, "c1", timeout_s=5)
        stack.callback(remote.close)
        first, second = remote.capture(), remote.capture()
        assert (first.source, second.source) == ("files:a.png", "files:b.png")
        np.testing.assert_array_equal(first.image, images["a.png"])
        assert remote.last_capture_meta is not None
        assert remote.last_capture_meta["heading_deg"] == 0.0  # no base on the bus
        # one camera per robot id: a robot node serving its camera refuses, one without starts
        with pytest.raises(bus.BusIdInUse, match="camera node"):
            RobotNode(session, "c1", _Base())
        with RobotNode(session, "c1", _Base(), serve_camera=False):
            assert remote.capture().source == "files:a.png"
            assert remote.last_capture_meta["heading_deg"] == pytest.approx(30.0)


def test_a_node_refuses_bad_input_in_one_line(tmp_path: Path) -> None:
    for args, expected in [
        (("camera", "--source", "sim"), "node robot"),
        (("camera", "--source", f"files:{tmp_path / 'none'}"), "is not a folder"),
        (("localizer", "--db", str(tmp_path / "none.db")), "does not exist"),
    ]:
        result = subprocess.run(
            [sys.executable, "-m", "toploc", "node", *args, "--robot-id", "bad1"],
            cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, capture_output=True,
            text=True, timeout=30,
        )  # fmt: skip
        errors = [line for line in result.stderr.splitlines() if line.startswith("Error")]
        assert result.returncode != 0 and len(errors) == 1 and expected in errors[0], result


class _Base:
    """A base without a camera, heading 30°."""

    def capture(self):
        raise AssertionError("the camera node captures, not the base")

    def move(self, turn_rad: float, forward_m: float):
        from localizer.robot_protocol import MoveResult

        return MoveResult(turn_rad, forward_m, False)

    def odometry(self):
        from localizer.robot_protocol import Pose2D

        return Pose2D(0.0, 0.0, np.radians(30.0))

    def stop(self) -> None:
        """Nothing moves."""


def test_sigusr1_prints_every_threads_stack_and_the_node_goes_on(tmp_path: Path, building_map):
    db = tmp_path / "map.db"
    shutil.copy(building_map[0], db)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with nodes(("map", "--db", str(db), "--listen", endpoint, "--robot-id", "n5")) as (node,):
        node.process.send_signal(signal.SIGUSR1)
        deadline = time.monotonic() + 10.0
        while not any("most recent call first" in line for line in node.output):
            assert time.monotonic() < deadline, node.output
            time.sleep(0.05)
        assert node.process.poll() is None
    assert node.process.returncode == 0 and node.output[-1] == "stopped"


@pytest.mark.parametrize(
    ("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 0)], ids=["ctrl-c", "sigterm"]
)
def test_serve_on_a_new_map_with_the_simulated_robot_waits_for_places_until_stopped(
    tmp_path: Path, signum: int, code: int
) -> None:
    db = tmp_path / "new.db"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    args = ("--db", str(db), "--new-map", "--listen", endpoint, "--robot-id", "s1")
    serve = Node(*args, command=("serve",))
    try:
        assert "serving" in serve.wait_ready(60.0)
        with (
            client_session(endpoint, "s1") as session,
            pytest.raises(bus.BusReplyError, match="the map has no places yet"),
        ):
            LocalizerClient(session, "s1", timeout_s=10).belief()
        serve.process.send_signal(signum)
        assert serve.process.wait(30) == code, "\n".join(serve.output)
    finally:
        serve.stop()
    assert serve.output[-1] == "stopped"
    assert db.exists()


def test_a_serve_that_refuses_to_start_leaves_no_new_map_behind(tmp_path: Path) -> None:
    db = tmp_path / "new.db"
    result = subprocess.run(
        [sys.executable, "-m", "toploc", "serve", "--db", str(db), "--new-map",
         "--source", f"files:{tmp_path / 'none'}", "--robot-id", "s2"],
        cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, capture_output=True,
        text=True, timeout=60,
    )  # fmt: skip
    assert result.returncode == 1 and "--source" in result.stderr, result
    assert sorted(tmp_path.iterdir()) == []
