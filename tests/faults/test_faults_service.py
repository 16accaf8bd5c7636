"""Hostile and unlucky bus clients (issue 11): each test is one of its reproductions, run on real
Zenoh sessions on 127.0.0.1. Before the fix each of them failed (a NaN belief, a 10 km drive,
abandoned queries run in turn, ...)."""

import math
import re
import sqlite3
import threading
import time

import cv2
import numpy as np
import pytest
from bus_helpers import ROBOT_ID, wait_for
from robot_helpers import RobotWrapper

from localizer.belief import BeliefFilter
from localizer.loaded_map import LoadedMap
from localizer.localizer import Localizer
from localizer.robot_protocol import Capture, MoveResult, Pose2D
from mapdb.database import MapDatabase
from mapdb.loading import load_snapshot
from mapdb.records import Fingerprint, NewPlace
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.worlds import make_world
from toploc import bus
from toploc.bus.png_codec import decode_png
from toploc.limits import Limits, RateLimit, load_limits
from toploc.nodes.localizer import LocalizerClient, LocalizerNode
from toploc.nodes.mapdb import MapNode
from toploc.nodes.robot import RemoteRobot, RobotNode
from toploc.runner import LocalizationDroppedError, LocalizationRunner


class SlowRobot:
    """A robot whose moves last until :meth:`stop` (or 10 s); records what it was asked."""

    def __init__(self) -> None:
        self.moves: list[tuple[float, float]] = []
        self.stopped = threading.Event()
        self.captures = 0

    def capture(self) -> Capture:
        self.captures += 1
        return Capture(np.zeros((8, 32), np.uint8), 0.0, "slow")

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        self.moves.append((turn_rad, forward_m))
        self.stopped.wait(10.0)
        return MoveResult(turn_rad, 0.0, False)

    def odometry(self) -> Pose2D:
        return Pose2D(0.0, 0.0, 0.0)

    def stop(self) -> None:
        self.stopped.set()


def command(zbus, payload: bytes, timeout_s: float = 3.0):
    return bus.request(zbus.client, bus.key(ROBOT_ID, bus.BASE_CMD), payload, timeout_s)


@pytest.fixture
def slow_robot(zbus):
    robot = SlowRobot()
    with RobotNode(zbus.server, ROBOT_ID, robot, Limits(move_timeout_s=0.5, max_captures_per_s=3)):
        zbus.wait_alive("robot")
        yield zbus, robot


# --- the belief ------------------------------------------------------------------------------


def test_huge_prior_weights_give_a_finite_belief():
    beliefs = BeliefFilter(["kitchen", "office_a"])
    beliefs.reset({"kitchen": 1e308, "office_a": 1e308})
    assert beliefs.as_dict() == {"kitchen": 0.5, "office_a": 0.5}


@pytest.fixture(scope="module")
def building(building_map) -> LoadedMap:
    return LoadedMap.from_snapshot(load_snapshot(building_map[0]))


def robot_in_kitchen() -> SimulatedRobot:
    world = make_world("building")
    pose = world.building_pose("kitchen", Pose2D(2.0, 3.0, math.radians(30.0)))
    return SimulatedRobot(world, pose, camera=PanoramaCamera(512, 96), seed=9)


def test_a_reset_with_huge_weights_over_the_bus_leaves_the_service_usable(zbus, building):
    runner = LocalizationRunner(Localizer(building), robot_in_kitchen())
    with LocalizerNode(zbus.server, ROBOT_ID, runner):
        zbus.wait_alive("localizer")
        client = LocalizerClient(zbus.client, ROBOT_ID, timeout_s=5.0, localize_timeout_s=30.0)
        reset = client.reset({"kitchen": 1e308, "office_a": 1e308})
        assert reset["rooms"]["kitchen"] == pytest.approx(0.5)
        assert all(math.isfinite(p) for p in client.belief()["rooms"].values())
        assert client.localize()["best_place"]["room"] == "kitchen"


def test_a_prior_naming_a_room_with_a_huge_name_is_refused_briefly(zbus, building):
    runner = LocalizationRunner(Localizer(building), robot_in_kitchen())
    with LocalizerNode(zbus.server, ROBOT_ID, runner):
        zbus.wait_alive("localizer")
        client = LocalizerClient(zbus.client, ROBOT_ID, timeout_s=5.0)
        with pytest.raises(bus.BusReplyError, match="10000 characters; at most 256") as error:
            client.reset({"k" * 10_000: 1.0})
    assert len(str(error.value)) < 300


# --- base/cmd --------------------------------------------------------------------------------


def test_a_drive_beyond_the_limit_is_refused_and_the_robot_does_not_move(slow_robot):
    zbus, robot = slow_robot
    with pytest.raises(bus.BusReplyError, match="forward_m 10000 is beyond the limit of 5 m"):
        command(zbus, bus.encode("cmd", {"turn_deg": 0.0, "forward_m": 10000}))
    assert robot.moves == []


def test_a_huge_turn_is_refused(slow_robot):
    zbus, robot = slow_robot
    with pytest.raises(bus.BusReplyError, match=r"turn_deg 1000000\.0 is beyond the limit of 360°"):
        command(zbus, bus.encode("cmd", {"turn_deg": 1e6, "forward_m": 0.0}))
    assert robot.moves == []


def test_a_message_of_another_kind_is_not_taken_as_a_command(slow_robot):
    zbus, robot = slow_robot
    with pytest.raises(bus.BusReplyError, match="message kind 'reset', expected 'cmd'"):
        command(zbus, bus.encode("reset", {"turn_deg": 10.0, "forward_m": 1.0}))
    assert robot.moves == []


def test_an_oversized_command_is_refused_before_parsing(slow_robot):
    zbus, robot = slow_robot
    padding = "x" * 70_000
    payload = bus.encode("cmd", {"turn_deg": 0.0, "forward_m": 1.0, "note": padding})
    with pytest.raises(bus.BusReplyError, match="bytes; at most 65536 are accepted"):
        command(zbus, payload)
    assert robot.moves == []


def test_a_move_past_its_timeout_is_stopped_and_answered(slow_robot):
    zbus, robot = slow_robot
    start = time.monotonic()
    with pytest.raises(bus.BusReplyError, match=r"did not finish within 0\.5 s; the base was"):
        command(zbus, bus.encode("cmd", {"turn_deg": 0.0, "forward_m": 1.0}))
    assert robot.stopped.is_set()
    assert time.monotonic() - start < 5.0  # the move itself would have lasted 10 s


def test_base_stop_ends_a_move_in_progress(slow_robot):
    zbus, robot = slow_robot
    remote = RemoteRobot(zbus.client, ROBOT_ID, timeout_s=2.0, move_timeout_s=5.0)
    results: list[MoveResult] = []
    mover = threading.Thread(target=lambda: results.append(remote.move(0.0, 1.0)))
    mover.start()
    assert wait_for(lambda: bool(robot.moves))
    remote.stop()
    mover.join(5.0)
    assert robot.stopped.is_set() and results == [MoveResult(0.0, 0.0, False)]
    remote.close()


def test_captures_beyond_the_rate_limit_are_refused_with_the_wait(slow_robot):
    zbus, robot = slow_robot
    key_expr = bus.key(ROBOT_ID, bus.CAMERA_CAPTURE)
    for _ in range(3):
        bus.request(zbus.client, key_expr, None, 2.0)
    with pytest.raises(
        bus.BusReplyError, match="rate limited: at most 3 captures per second"
    ) as refused:
        bus.request(zbus.client, key_expr, None, 2.0)
    assert refused.value.retry_after_s is not None and 0.0 < refused.value.retry_after_s <= 1.0
    assert robot.captures == 3


def test_the_remote_robot_waits_its_turn_at_the_rate_limit(slow_robot):
    zbus, robot = slow_robot
    remote = RemoteRobot(zbus.client, ROBOT_ID, timeout_s=2.0)
    start_s = time.monotonic()
    for _ in range(5):  # 3 per second: the 4th and 5th wait for the window
        remote.capture()
    assert robot.captures == 5
    assert time.monotonic() - start_s > 0.5
    remote.close()


def test_the_remote_robot_gives_up_when_the_wait_outlasts_its_timeout(slow_robot):
    zbus, _ = slow_robot
    remote = RemoteRobot(zbus.client, ROBOT_ID, timeout_s=0.2)
    for _ in range(3):
        remote.capture()
    with pytest.raises(bus.BusReplyError, match="rate limited"):
        remote.capture()
    remote.close()


def test_the_rate_limit_admits_again_after_its_window():
    limit = RateLimit(2, window_s=1.0)
    assert [limit.allow(t) for t in (0.0, 0.1, 0.2, 1.05, 1.15)] == [True, True, False, True, True]


def test_the_rate_limit_says_how_long_to_wait():
    limit = RateLimit(2, window_s=1.0)
    assert limit.wait_s(0.0) == 0.0
    limit.allow(0.0)
    limit.allow(0.3)
    assert limit.wait_s(0.5) == pytest.approx(0.5)  # the event at 0.0 leaves at 1.0
    assert limit.wait_s(0.9) == pytest.approx(0.1)
    assert limit.wait_s(1.0) == 0.0  # it left the window
    from_toml = RateLimit(2.0, window_s=1.0)  # type: ignore[arg-type]  # a TOML file's 2.0
    assert [from_toml.allow(t) for t in (0.0, 0.1, 0.2)] == [True, True, False]
    assert from_toml.wait_s(0.5) == pytest.approx(0.5)


# --- localizer/localize ----------------------------------------------------------------------


class GatedRobot(RobotWrapper):
    """The kitchen robot, whose captures wait for ``gate`` and are counted."""

    def __init__(self) -> None:
        super().__init__(robot_in_kitchen())
        self.gate = threading.Event()
        self.captures = 0

    def capture(self) -> Capture:
        self.captures += 1
        self.gate.wait(10.0)
        return self.robot.capture()


def test_localize_queries_whose_clients_gave_up_are_dropped_unrun(zbus, building):
    robot = GatedRobot()
    runner = LocalizationRunner(Localizer(building), robot)
    with LocalizerNode(zbus.server, ROBOT_ID, runner):
        zbus.wait_alive("localizer")
        patient = LocalizerClient(zbus.client, ROBOT_ID, localize_timeout_s=30.0)
        first = threading.Thread(target=patient.localize)
        first.start()
        assert wait_for(lambda: robot.captures == 1)
        hasty = LocalizerClient(zbus.client, ROBOT_ID, localize_timeout_s=0.3)
        for _ in range(5):
            with pytest.raises((bus.BusTimeout, bus.BusReplyError)):  # whichever ends first
                hasty.localize()
        robot.gate.set()
        first.join(10.0)
        start = time.monotonic()
        patient.localize()
        fresh_s = time.monotonic() - start
    assert robot.captures == 2  # the first and the fresh one; the five abandoned never ran
    assert fresh_s < 5.0


def test_localizations_beyond_the_queue_bound_are_refused_at_once(building):
    robot = GatedRobot()
    runner = LocalizationRunner(Localizer(building), robot, max_pending=1)
    first = threading.Thread(target=runner.localize, args=(False,))
    first.start()
    assert wait_for(lambda: robot.captures == 1)
    waiting = threading.Thread(target=runner.localize, args=(False, time.monotonic() + 10.0))
    waiting.start()
    assert wait_for(lambda: runner._pending == 1)
    with pytest.raises(LocalizationDroppedError, match="1 localizations are already waiting"):
        runner.localize(False)
    robot.gate.set()
    first.join(10.0)
    waiting.join(10.0)


# --- limits files ----------------------------------------------------------------------------


def test_a_limits_file_overrides_some_bounds(tmp_path):
    path = tmp_path / "limits.toml"
    path.write_text("max_forward_m = 2.0\nmove_timeout_s = 30\n")
    assert load_limits(path) == Limits(max_forward_m=2.0, move_timeout_s=30.0)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("max_forward_m = -1\n", "max_forward_m must be finite and > 0"),
        ("max_speed = 1\n", "unknown limit(s) ['max_speed']"),
        ("max_forward_m = 'far'\n", "max_forward_m must be a number"),
        ("max_pending_localizations = 2.5\n", "must be an integer"),
        ("max_forward_m = \n", "cannot read the limits"),
    ],
)
def test_a_bad_limits_file_is_named_in_one_line(tmp_path, text, message):
    path = tmp_path / "limits.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=re.escape(message)) as err:
        load_limits(path)
    assert str(err.value).startswith(str(path)) and "\n" not in str(err.value)


# --- map/places ------------------------------------------------------------------------------


def test_a_place_stored_with_an_infinite_position_is_served_as_null(zbus, tmp_path):
    """Before: one inf (stored by an older toploc) made ``map/places`` fail for every client."""
    db_path = tmp_path / "map.db"
    with MapDatabase.open(db_path) as map_db:
        place = NewPlace("office_a", "ab" * 32, "a.png", x_m=1.0, y_m=2.0, heading_deg=90.0)
        map_db.add_place(place, [Fingerprint.empty("sift", 96, 24)])
    with sqlite3.connect(db_path) as raw:  # what the write path now refuses
        raw.execute("UPDATE places SET x_m = 9e999")
    raw.close()
    with MapNode(zbus.server, ROBOT_ID, db_path):
        zbus.wait_alive("mapdb")
        key_expr = bus.key(ROBOT_ID, bus.MAP_PLACES)
        places = bus.request_json(zbus.client, key_expr, {"places": list}, None, 2.0)["places"]
    assert [(p["x_m"], p["y_m"]) for p in places] == [(None, 2.0)]


def test_an_oversized_capture_is_refused_from_its_header():
    png = cv2.imencode(".png", np.zeros((4000, 20000), np.uint8))[1].tobytes()  # 80 MP, a few kB
    with pytest.raises(bus.BusMessageError, match="image is 20000x4000 px; at most 75000000"):
        decode_png("camera/capture", png)


class CameraHoldsTheLock(SlowRobot):
    """A robot whose capture takes ``capture_s`` (a pan sweep re-stitched, a slow webcam)."""

    def __init__(self, capture_s: float) -> None:
        super().__init__()
        self.capture_s = capture_s

    def capture(self) -> Capture:
        time.sleep(self.capture_s)
        return super().capture()


def test_a_stop_while_a_move_waits_for_the_robot_cancels_it(zbus):
    robot = CameraHoldsTheLock(capture_s=1.0)
    with RobotNode(zbus.server, ROBOT_ID, robot):
        zbus.wait_alive("robot")
        remote = RemoteRobot(zbus.client, ROBOT_ID, timeout_s=5.0, move_timeout_s=5.0)
        capturing = threading.Thread(target=remote.capture)
        capturing.start()
        time.sleep(0.2)  # the capture holds the robot lock for a second
        outcome: list[object] = []

        def move() -> None:
            try:
                outcome.append(remote.move(0.0, 1.0))
            except bus.BusReplyError as error:
                outcome.append(error)

        mover = threading.Thread(target=move)
        mover.start()
        time.sleep(0.2)  # the move is accepted and waits for the lock
        remote.stop()
        mover.join(10.0)
        capturing.join(10.0)
        remote.close()
    assert robot.moves == []  # before: the move started after the stop and drove 1 m
    assert isinstance(outcome[0], bus.BusReplyError)
    assert "base/stop came before the move started" in str(outcome[0])
