"""The homing node over Zenoh on 127.0.0.1: a service with the simulated robot in the small
rendered building, goals to its places, progress, cancel, busy, stop, and the active localizer
driving through the same node."""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from bus_helpers import free_endpoint, wait_for

from localizer.loaded_map import LoadedMap
from localizer.localizer import Localizer
from localizer.robot_protocol import Capture, MoveResult, Pose2D, Robot
from mapdb.loading import load_snapshot
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.worlds import make_world
from toploc import bus
from toploc.bus import BusConfig, open_session
from toploc.nodes.homing import HomingClient, HomingService
from toploc.nodes.localizer import LocalizerClient
from toploc.runner import LocalizationRunner
from toploc.service import Service, start_service

CAMERA = PanoramaCamera(512, 96)
KITCHEN_PLACE = 17  # kitchen (2.25, 0.75) in the building map of tests/conftest.py
ROBOT_ID = "h1"


def near_kitchen_place() -> SimulatedRobot:
    """0.7 m from place 17, in the kitchen."""
    world = make_world("building")
    pose = world.building_pose("kitchen", Pose2D(2.85, 1.15, math.radians(30.0)))
    return SimulatedRobot(world, pose, camera=CAMERA, seed=9)


class SlowRobot:
    """A simulated robot whose moves take ``move_s`` unless stopped; counts its stops."""

    def __init__(self, robot: SimulatedRobot, move_s: float = 0.4) -> None:
        self.robot, self.move_s = robot, move_s
        self.stops = 0
        self.stopped = threading.Event()

    def capture(self) -> Capture:
        return self.robot.capture()

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        self.stopped.clear()
        self.stopped.wait(self.move_s)
        return self.robot.move(turn_rad, forward_m)

    def odometry(self) -> Pose2D:
        return self.robot.odometry()

    def stop(self) -> None:
        self.stops += 1
        self.stopped.set()
        self.robot.stop()


@contextmanager
def homing_service(
    db_path: Path, robot: Robot
) -> Iterator[tuple[Service, HomingClient, list[dict]]]:
    """The service with ``robot``, a client session, and the progress messages it receives."""
    endpoint = free_endpoint()
    service_config = BusConfig(robot_id=ROBOT_ID, listen=(endpoint,))
    client_config = BusConfig(robot_id=ROBOT_ID, listen=(), connect=(endpoint,))
    progress: list[dict] = []
    with (
        start_service(db_path, service_config, robot, recalibrate=False) as service,
        open_session(client_config) as session,
    ):
        client = HomingClient(session, ROBOT_ID, timeout_s=5.0)
        client.subscribe(progress.append)
        # the subscription reaches the service asynchronously: a cancel is answered once it is up
        time.sleep(0.3)
        yield service, client, progress
        client.close()


def run_goal(client: HomingClient, place_id: int, results: list, timeout_s: float = 30.0):
    def goal() -> None:
        try:
            results.append(client.goal(place_id, timeout_s))
        except bus.BusError as error:
            results.append(error)

    worker = threading.Thread(target=goal)
    worker.start()
    return worker


def test_each_drive_ends_with_a_log_line_of_its_place_room_and_how_it_ended(building_map, caplog):
    """A service owner reads each drive of an active localization in the log, not only its
    end: where to, how it ended, how far."""
    localizer = Localizer(LoadedMap.from_snapshot(load_snapshot(building_map[0])))
    homing = HomingService(LocalizationRunner(localizer, near_kitchen_place()))
    with caplog.at_level(logging.INFO, logger="toploc.nodes.homing"):
        result = homing.home(KITCHEN_PLACE)
    # only the homing node's own lines: a service another test stopped may still log as it ends
    lines = [r.getMessage() for r in caplog.records if r.name == "toploc.nodes.homing"]
    assert lines == [
        f"homing to place {KITCHEN_PLACE} (kitchen): {result.reason} after {result.steps} "
        f"moves, {result.distance_m:.2f} m"
    ]


def test_a_goal_in_the_robots_room_arrives_and_publishes_progress(building_map):
    robot = near_kitchen_place()
    with homing_service(building_map[0], robot) as (_, client, progress):
        reply = client.goal(KITCHEN_PLACE, timeout_s=30.0)
        assert wait_for(lambda: progress and progress[-1]["state"] == reply["reason"])
    assert reply["arrived"] and reply["reason"] in ("arrived", "converged"), reply
    assert reply["place_id"] == KITCHEN_PLACE and reply["steps"] >= 1
    assert reply["distance_m"] == pytest.approx(robot.distance_driven_m, abs=1e-6)
    world = make_world("building")
    goal = world.building_pose("kitchen", Pose2D(2.25, 0.75, 0.0))
    end = robot.true_pose
    assert math.hypot(end.x_m - goal.x_m, end.y_m - goal.y_m) < 0.35
    steps = [m for m in progress if m["state"] == "homing"]
    assert len(steps) >= 2 and all(m["place_id"] == KITCHEN_PLACE for m in progress)
    assert all(m["matched"] >= 6 and m["features"] >= m["matched"] for m in steps)
    assert steps[-1]["home_length"] < steps[0]["home_length"]
    assert [m["step"] for m in progress] == sorted(m["step"] for m in progress)
    assert progress[-1]["step"] == reply["steps"]
    assert progress[-1]["moved_m"] == pytest.approx(reply["distance_m"])


def test_an_unknown_or_malformed_goal_is_an_error_and_the_robot_does_not_move(building_map):
    robot = near_kitchen_place()
    with homing_service(building_map[0], robot) as (_, client, _progress):
        with pytest.raises(bus.BusReplyError, match=r"homing/goal: unknown place_id 999"):
            client.goal(999, timeout_s=5.0)
        key = bus.key(ROBOT_ID, bus.HOMING_GOAL)
        bad = bus.encode("goal", {"place_id": "17"})
        with pytest.raises(bus.BusReplyError, match="'place_id' must be int"):
            bus.request(client.session, key, bad, timeout_s=5.0)
        huge = bus.encode("goal", {"place_id": 17, "note": "x" * 70_000})
        with pytest.raises(bus.BusReplyError, match="at most 65536 are accepted"):
            bus.request(client.session, key, huge, timeout_s=5.0)
        negative = bus.encode("goal", {"place_id": 17, "timeout_s": -1})
        with pytest.raises(bus.BusReplyError, match="timeout_s must be a number > 0"):
            bus.request(client.session, key, negative, timeout_s=5.0)
        assert client.cancel() is False
    assert robot.distance_driven_m == 0


def test_cancel_during_a_goal_stops_it_and_the_robot(building_map):
    robot = SlowRobot(near_kitchen_place())
    results: list = []
    with homing_service(building_map[0], robot) as (_, client, progress):
        worker = run_goal(client, KITCHEN_PLACE, results)
        assert wait_for(lambda: bool(progress), 10.0)
        second: list = []
        run_goal(client, KITCHEN_PLACE, second).join(5.0)
        stops_before = robot.stops
        start = time.monotonic()
        assert client.cancel() is True
        worker.join(10.0)
        elapsed_s = time.monotonic() - start
    assert isinstance(second[0], bus.BusReplyError) and "busy: homing to place 17" in str(second[0])
    reply = results[0]
    assert (reply["arrived"], reply["reason"]) == (False, "cancelled")
    assert robot.stops > stops_before  # base/stop at once, not at the end of the move
    assert elapsed_s < 2.0
    assert progress[-1]["state"] == "cancelled" and progress[-1]["step"] == reply["steps"]


class RefusingRobot(SlowRobot):
    """Its base refuses a move that a stop overtook, as the robot node does ("base/stop came
    before the move started: not moved")."""

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        self.stopped.clear()
        if self.stopped.wait(self.move_s):
            raise RuntimeError("base/stop came before the move started: not moved")
        return self.robot.move(turn_rad, forward_m)


def test_a_move_the_base_refuses_because_of_the_cancel_ends_as_cancelled(building_map):
    robot = RefusingRobot(near_kitchen_place(), move_s=5.0)
    results: list = []
    with homing_service(building_map[0], robot) as (_, client, progress):
        worker = run_goal(client, KITCHEN_PLACE, results)
        assert wait_for(lambda: bool(progress), 10.0)
        assert client.cancel() is True
        worker.join(10.0)
    assert not isinstance(results[0], Exception), results[0]
    assert (results[0]["arrived"], results[0]["reason"]) == (False, "cancelled")


def test_a_goal_times_out_and_the_runner_stop_ends_a_goal(building_map):
    robot = SlowRobot(near_kitchen_place(), move_s=2.0)
    with homing_service(building_map[0], robot) as (service, client, _progress):
        reply = client.goal(KITCHEN_PLACE, timeout_s=0.5)
        assert (reply["arrived"], reply["reason"]) == (False, "timeout")
        results: list = []
        worker = run_goal(client, KITCHEN_PLACE, results)
        assert wait_for(lambda: service.homing is not None and service.homing.running(), 10.0)
        time.sleep(0.2)
        start = time.monotonic()
        assert service.runner.stop(wait_s=5.0)
        stopped_s = time.monotonic() - start
        worker.join(10.0)
    assert stopped_s < 2.0
    assert isinstance(results[0], bus.BusReplyError) and "the service is stopping" in str(
        results[0]
    )


def test_active_localization_drives_through_the_homing_node(building_map):
    robot = SimulatedRobot.kidnapped(make_world("building"), "office_b", seed=4, camera=CAMERA)
    with homing_service(building_map[0], robot) as (_, client, progress):
        localizer = LocalizerClient(client.session, ROBOT_ID, timeout_s=5.0)
        beliefs: list[dict] = []
        localizer.subscribe(beliefs.append)
        time.sleep(0.2)
        belief = localizer.localize(active=True)
        assert wait_for(lambda: bool(progress) and progress[-1]["state"] != "homing")
        localizer.close()
    assert any(b["state"] == "homing" for b in beliefs), "the first look was not ambiguous"
    assert belief["top"]["room"] == "office_b"
    assert progress and {m["state"] for m in progress} & {"homing", "lost"}
    driven = sum(m["moved_m"] for m in progress if m["state"] not in ("homing", "lost"))
    assert driven == pytest.approx(robot.distance_driven_m, abs=1e-6)


def test_a_cancel_during_active_localization_ends_its_driving(building_map):
    kidnapped = SimulatedRobot.kidnapped(make_world("building"), "office_b", seed=4, camera=CAMERA)
    robot = SlowRobot(kidnapped, move_s=2.0)
    with homing_service(building_map[0], robot) as (_, client, progress):
        localizer = LocalizerClient(client.session, ROBOT_ID, timeout_s=5.0)
        beliefs: list[dict] = []
        worker = threading.Thread(target=lambda: beliefs.append(localizer.localize(active=True)))
        worker.start()
        assert wait_for(lambda: bool(progress), 15.0)
        assert client.cancel() is True
        worker.join(10.0)
        assert wait_for(lambda: progress[-1]["state"] == "cancelled")
    assert beliefs and beliefs[0]["kind"] == "belief"  # it looked where the robot stopped
    assert [m["state"] for m in progress].count("cancelled") == 1
    assert kidnapped.distance_driven_m < 1.0  # one move at most: no further drive


def test_the_docs_homing_example_runs(building_map, capsys):
    page = Path(__file__).resolve().parents[2] / "docs" / "bus.md"
    section = page.read_text(encoding="utf-8").split("## Homing over the bus", 1)[1]
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    with homing_service(building_map[0], near_kitchen_place()) as (service, _client, progress):
        code = code.replace('"tcp/127.0.0.1:7447"', repr(service.config.listen[0]))
        code = code.replace("config.robot_id", repr(ROBOT_ID))
        exec(compile(code, "docs/bus.md", "exec"), {})
        assert wait_for(lambda: bool(progress) and progress[-1]["state"] != "homing")
    out = capsys.readouterr().out.splitlines()
    assert {"arrived", "converged"} & set(out), out  # the reply (progress lines have 4 words)
