"""``toploc belief --watch``: the block it draws, and the watch on a real Zenoh bus (127.0.0.1):
an active localization followed to its end, a plain watch ended by Ctrl-C."""

from __future__ import annotations

import io
import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from bus_helpers import ROBOT_ID, Bus, free_endpoint, make_belief, wait_for
from click.testing import CliRunner

from toploc import bus
from toploc.cli import main
from toploc.commands.belief_watch import ASCII_BLOCKS, Screen, render_watch
from toploc.nodes.localizer import LocalizerNode
from toploc.runner import NoPlacesYetError

REPO = Path(__file__).resolve().parents[2]
STAMP = 1764615296.25


def belief(rooms: dict[str, float], state: str, stamp: float = STAMP) -> dict:
    """A belief message as the localizer node sends it."""
    return make_belief(rooms, state, stamp)


def progress(step: int, state: str = "homing") -> dict:
    return {
        "schema": bus.SCHEMA_VERSION, "kind": "progress", "place_id": 4, "step": step,
        "features": 310, "matched": 40, "home_length": 0.31, "parallax_deg": 4.2,
        "moved_m": 1.2, "state": state,
    }  # fmt: skip


def wait_subscribed(session, suffix: str) -> None:
    """Wait until ``session`` knows a subscriber of ``suffix`` (a publication before that is
    not sent: the watch would miss it)."""
    probe = session.declare_publisher(bus.key(ROBOT_ID, suffix))
    try:
        assert wait_for(lambda: probe.matching_status.matching, 5.0), f"nobody on {suffix}"
    finally:
        probe.undeclare()


def clock(stamp: float) -> str:
    return time.strftime("%H:%M:%S", time.localtime(stamp))


def test_a_block_shows_state_bars_best_place_and_the_drive():
    lines = render_watch(belief({"office_b": 0.81, "lab": 0.19}, "homing"), progress(3))
    assert lines == [
        f"state: homing   entropy: 0.701 bits   stamp: {STAMP:.3f} ({clock(STAMP)})",
        "  office_b  ████████████████░░░░  0.810",
        "  lab       ████░░░░░░░░░░░░░░░░  0.190",
        "best place: 4 in office_b (37 inliers)",
        "drive to place 4: step 3, moved 1.20 m, 40/310 matched, home 0.31, parallax 4.2 deg "
        "(homing)",
    ]


def test_the_reply_to_an_active_localization_says_how_it_went():
    reply = {
        **belief({"office_b": 0.97, "office_a": 0.03}, "localized"),
        "active": {"drives": 2, "distance_m": 1.66, "ended": "settled"},
    }
    assert render_watch(reply)[-1] == "active: 2 drives, 1.66 m; settled"


def test_a_belief_that_waits_for_a_room_seen_in_part_says_why():
    waiting = {
        **belief({"office_b": 0.99, "lab": 0.01}, "ambiguous"),
        "partly_seen": {"room": "office_b", "horizon_share": 0.4, "needed_share": 0.6},
    }
    assert render_watch(waiting)[-1].startswith("waits: office_b seen on 40% of the horizon")


def test_a_stale_belief_and_an_ended_drive_say_so():
    stale = {**belief({"lab": 1.0}, "localized"), "stale": True, "age_s": 12.0}
    lines = render_watch(stale, progress(5, "arrived"))
    assert lines[0].endswith("STALE: the robot node is gone (12 s)")
    assert lines[-1].startswith("last drive to place 4: step 5,") and "(arrived)" in lines[-1]


def test_a_terminal_redraws_the_block_in_place_and_a_pipe_appends_blocks():
    terminal, pipe = io.StringIO(), io.StringIO()
    for out, tty in ((terminal, True), (pipe, False)):
        screen = Screen(out, tty)
        screen.show(["a", "b"])
        screen.show(["a", "b"])  # unchanged: not drawn again
        screen.show(["c"])
    assert terminal.getvalue() == "a\nb\n\x1b[2F\x1b[Jc\n"
    assert pipe.getvalue() == "a\nb\n\nc\n"


def test_a_stream_that_cannot_encode_the_blocks_gets_ascii_bars():
    ascii_out = io.TextIOWrapper(io.BytesIO(), encoding="ascii")
    screen = Screen(ascii_out, tty=False)
    assert screen.blocks == ASCII_BLOCKS
    assert "  lab   ##########..........  0.500" in render_watch(
        belief({"lab": 0.5, "hall": 0.5}, "ambiguous"), blocks=screen.blocks
    )


class DrivingService:
    """A localizer whose active localization publishes a homing belief and the drive's
    progress (as the service's runner and homing node do), then ends localized."""

    def __init__(self, progress_publisher) -> None:
        self.current = belief({"office_b": 0.5, "lab": 0.5}, "ambiguous")
        self.progress_publisher = progress_publisher
        self.node: LocalizerNode | None = None

    def belief(self) -> dict:
        return self.current

    def localize(self, active: bool, deadline_s: float | None = None) -> dict:
        assert active and self.node is not None
        for suffix in (bus.LOCALIZER_BELIEF, bus.HOMING_PROGRESS):
            wait_subscribed(self.node.session, suffix)
        self.node.publish(belief({"office_b": 0.6, "lab": 0.4}, "homing", STAMP + 1))
        for message in (progress(1), progress(2), progress(2, "arrived")):
            self.progress_publisher.put(json.dumps(message).encode())
        self.current = belief({"office_b": 0.97, "lab": 0.03}, "localized", STAMP + 2)
        return self.current

    def reset(self, prior) -> dict:
        return self.current


@pytest.fixture
def driving(zbus: Bus):
    publisher = zbus.server.declare_publisher(bus.key(ROBOT_ID, bus.HOMING_PROGRESS))
    service = DrivingService(publisher)
    with LocalizerNode(zbus.server, ROBOT_ID, service) as node:
        service.node = node
        zbus.wait_alive("localizer")
        yield zbus, service, node
    publisher.undeclare()


def watch(endpoint: str, *args: str):
    base = ["belief", "--watch", "--robot-id", ROBOT_ID, "--connect", endpoint, "--timeout", "5"]
    return CliRunner().invoke(main, [*base, *args])


def test_watch_active_follows_the_localization_and_its_drive_to_the_end(driving):
    zbus, _, _ = driving
    done = watch(zbus.endpoint, "--active")
    assert done.exit_code == 0, done.output
    blocks = done.stdout.split("\n\n")
    assert [block.splitlines()[0].split()[1] for block in blocks] == [
        "ambiguous", "homing", "homing", "homing", "homing", "localized",
    ]  # fmt: skip
    assert "  office_b  ████████████░░░░░░░░  0.600" in blocks[1]
    assert blocks[2].splitlines()[-1].startswith("drive to place 4: step 1, moved 1.20 m")
    assert blocks[4].splitlines()[-1].startswith("last drive to place 4: step 2")
    assert "  office_b  ███████████████████░  0.970" in blocks[5]


def test_watch_json_prints_one_message_per_line(driving):
    zbus, service, _ = driving
    done = watch(zbus.endpoint, "--active", "--json")
    assert done.exit_code == 0, done.output
    messages = [json.loads(line) for line in done.stdout.splitlines()]
    assert [(m["kind"], m["state"]) for m in messages] == [
        ("belief", "ambiguous"), ("belief", "homing"), ("progress", "homing"),
        ("progress", "homing"), ("progress", "arrived"), ("belief", "localized"),
    ]  # fmt: skip
    assert messages[-1] == service.current


def test_watch_without_a_service_fails_clearly():
    done = watch(free_endpoint(), "--timeout", "0.3")
    assert done.exit_code == 1
    assert f"Error: toploc/{ROBOT_ID}/localizer/belief: no reply" in done.output


def test_watch_shows_each_new_belief_until_ctrl_c(driving):
    zbus, _, node = driving
    env = {**os.environ, "PYTHONPATH": str(REPO), "PYTHONUNBUFFERED": "1"}
    args = ["belief", "--watch", "--robot-id", ROBOT_ID, "--connect", zbus.endpoint]
    process = subprocess.Popen(
        [sys.executable, "-m", "toploc", *args], cwd=REPO, env=env,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, encoding="utf-8",
    )  # fmt: skip
    lines: queue.Queue[str] = queue.Queue()
    assert process.stdout is not None
    threading.Thread(target=lambda: [lines.put(x) for x in process.stdout], daemon=True).start()

    def next_state(timeout_s: float = 20.0) -> str:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                line = lines.get(timeout=0.1)
            except queue.Empty:
                assert process.poll() is None, process.communicate()
                continue
            if line.startswith("state: "):
                return line.split()[1]
        raise AssertionError("no new block")

    try:
        assert next_state() == "ambiguous"
        wait_subscribed(zbus.server, bus.LOCALIZER_BELIEF)
        node.publish(belief({"office_b": 0.2, "lab": 0.8}, "localized", STAMP + 5))
        assert next_state() == "localized"
        process.send_signal(signal.SIGINT)
        assert process.wait(20) == 130
        assert process.stderr is not None and "interrupted" in process.stderr.read()
    finally:
        if process.poll() is None:
            process.kill()


class EmptyMapService(DrivingService):
    """A service whose map has no places yet, until its first localization."""

    def belief(self) -> dict:
        raise NoPlacesYetError("the map has no places yet: record some first")

    def localize(self, active: bool, deadline_s: float | None = None) -> dict:
        return belief({"kitchen": 1.0}, "localized", STAMP + 3)


def test_watch_says_why_there_is_no_belief_yet_and_goes_on(zbus):
    with LocalizerNode(zbus.server, ROBOT_ID, EmptyMapService(None)):
        zbus.wait_alive("localizer")
        done = watch(zbus.endpoint, "--localize")
    assert done.exit_code == 0, done.output
    first, last = done.stdout.split("\n\n")
    assert first == (
        f"no belief yet: toploc/{ROBOT_ID}/localizer/belief: NoPlacesYetError: the map has no "
        "places yet: record some first"
    )
    assert last.startswith("state: localized") and "  kitchen  ████████████████████  1.000" in last


def test_a_lost_belief_shows_no_room_as_the_answer() -> None:
    lines = render_watch(belief({"office_b": 1.0, "office_a": 0.0}, "lost"))
    assert lines[0].startswith("state: lost")
    assert lines[1] == "  lost: no room of the map matches (best office_b, 37 inliers)"
    assert not any("1.000" in line for line in lines)
