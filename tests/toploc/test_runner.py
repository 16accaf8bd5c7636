"""The localization service: the runner's thread safety, the service over Zenoh on loopback,
and ``toploc demo`` end to end on the small rendered map."""

from __future__ import annotations

import contextlib
import logging
import math
import shutil
import threading
from dataclasses import replace

import pytest
from bus_helpers import free_endpoint
from click.testing import CliRunner
from robot_helpers import RobotWrapper

from localizer.active import ENDINGS
from localizer.loaded_map import LoadedMap
from localizer.localizer import Localizer
from localizer.robot_protocol import Pose2D
from mapdb.loading import load_snapshot
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.worlds import make_world
from toploc.bus import BusConfig, open_session
from toploc.bus.messages import check_belief
from toploc.cli import main
from toploc.nodes.localizer import LocalizerClient
from toploc.runner import LocalizationRunner, LocalizationStoppedError, NoPlacesYetError
from toploc.service import start_service

CAMERA = PanoramaCamera(512, 96)


def robot_in(room: str, x_m: float, y_m: float) -> SimulatedRobot:
    world = make_world("building")
    pose = world.building_pose(room, Pose2D(x_m, y_m, math.radians(30.0)))
    return SimulatedRobot(world, pose, camera=CAMERA, seed=9)


class GatedRobot(RobotWrapper):
    """A simulated robot whose capture waits until the test opens the gate."""

    def __init__(self, robot: SimulatedRobot) -> None:
        super().__init__(robot)
        self.gate, self.waiting = threading.Event(), threading.Event()

    def capture(self):
        self.waiting.set()
        self.gate.wait(10)
        return self.robot.capture()


class LateStopRobot(RobotWrapper):
    """A base whose move lets a stop in after the caller's stopping check and before the move
    starts, then clears it on starting (as ``P2osBase.move`` does), and drives for ``move_s``
    unless stopped again."""

    def __init__(self, robot: SimulatedRobot, move_s: float = 30.0) -> None:
        super().__init__(robot)
        self.move_s = move_s
        self.moving, self.stopped = threading.Event(), threading.Event()
        self.stops = 0
        self.cut_short: bool | None = None

    def move(self, turn_rad: float, forward_m: float):
        self.moving.set()
        while self.stops == 0:  # the first stop lands in the window
            self.stopped.wait(0.01)
        self.stopped.clear()  # the move starts and forgets it
        self.cut_short = self.stopped.wait(self.move_s)
        return self.robot.move(turn_rad, forward_m)

    def stop(self) -> None:
        self.stops += 1
        self.stopped.set()
        self.robot.stop()


@pytest.fixture(scope="module")
def loaded(building_map) -> LoadedMap:
    return LoadedMap.from_snapshot(load_snapshot(building_map[0]))


def test_a_passive_localize_publishes_a_belief_in_the_bus_format(loaded):
    published = []
    runner = LocalizationRunner(Localizer(loaded), robot_in("kitchen", 2.0, 3.0))
    runner.publish = published.append
    belief = runner.localize(active=False)
    check_belief("test", belief)
    assert max(belief["rooms"], key=belief["rooms"].get) == "kitchen"
    assert belief["best_place"]["room"] == "kitchen"
    assert published[-1] == belief


def test_an_active_localize_replies_how_it_went_beside_its_belief(loaded):
    published = []
    runner = LocalizationRunner(Localizer(loaded), robot_in("kitchen", 2.0, 3.0))
    runner.publish = published.append
    reply = runner.localize(active=True)
    assert check_belief("test", reply)["active"] == reply["active"]
    assert set(reply["active"]) == {"drives", "distance_m", "ended"}
    assert reply["active"]["ended"] in ENDINGS
    assert "active" not in runner.belief()


class NoOdometryRobot(RobotWrapper):
    """A camera on the bus without a base: its odometry query times out."""

    asked = 0

    def odometry(self):
        self.asked += 1
        raise TimeoutError("no reply on toploc/test/base/odom")


def test_passive_localizations_from_one_spot_count_as_one_look(loaded):
    runner = LocalizationRunner(Localizer(loaded), robot_in("office_b", 2.5, 2.5))
    first = runner.localize(active=False)
    for _ in range(3):  # a client asking again and again while the robot stands still
        again = runner.localize(active=False)
    assert first["state"] == again["state"] == "ambiguous"
    assert again["rooms"]["office_b"] == pytest.approx(first["rooms"]["office_b"], abs=0.02)


class Walker(RobotWrapper):
    """Stands in one room, then in another ``moved_m`` on by odometry (it does not drive)."""

    def __init__(self, first: SimulatedRobot, then: SimulatedRobot, moved_m: float) -> None:
        super().__init__(first)
        self.then, self.moved_m, self.walked = then, moved_m, False

    def walk(self) -> None:
        self.robot, self.walked = self.then, True

    def odometry(self):
        return Pose2D(self.moved_m if self.walked else 0.0, 0.0, 0.0)


@pytest.mark.parametrize(
    ("room", "x_m", "y_m", "moved_m", "doors"),
    [
        ("corridor", 1.5, 2.0, 4.0, True),  # out of the kitchen's door
        ("seminar", 1.0, 1.5, 9.0, True),  # two doors on, unseen
        ("corridor", 1.5, 2.0, 4.0, False),  # a map without doors, as one of photos
    ],
)
def test_passive_localizations_follow_a_robot_that_went_on_into_another_room(
    loaded, room, x_m, y_m, moved_m, doors
):
    robot = Walker(robot_in("kitchen", 2.0, 3.0), robot_in(room, x_m, y_m), moved_m)
    runner = LocalizationRunner(Localizer(loaded if doors else replace(loaded, edges=())), robot)
    runner.localize(active=False)
    before = runner.localize(active=False)
    robot.walk()
    after = runner.localize(active=False)
    assert before["state"] == "localized" and before["rooms"]["kitchen"] > 0.99
    assert max(after["rooms"], key=after["rooms"].get) == room


def test_a_camera_without_odometry_asked_again_on_one_spot_counts_once(loaded):
    runner = LocalizationRunner(Localizer(loaded), NoOdometryRobot(robot_in("office_b", 2.5, 2.5)))
    first = runner.localize(active=False)
    for _ in range(3):  # the images say the camera has not moved
        again = runner.localize(active=False)
    assert first["state"] == again["state"] == "ambiguous"
    assert again["rooms"]["office_b"] == pytest.approx(first["rooms"]["office_b"], abs=0.02)


def test_a_robot_without_odometry_localizes_passively_and_is_asked_once(loaded, caplog):
    robot = NoOdometryRobot(robot_in("kitchen", 2.0, 3.0))
    runner = LocalizationRunner(Localizer(loaded), robot)
    with caplog.at_level(logging.WARNING, logger="toploc.runner"):
        runner.localize(active=False)
        belief = runner.localize(active=False)
    assert max(belief["rooms"], key=belief["rooms"].get) == "kitchen"
    assert robot.asked == 1
    assert "no odometry from the robot" in caplog.text


def test_belief_answers_and_reset_is_refused_while_a_localization_runs(loaded):
    robot = GatedRobot(robot_in("kitchen", 2.0, 3.0))
    runner = LocalizationRunner(Localizer(loaded), robot)
    before = runner.belief()
    worker = threading.Thread(target=runner.localize, args=(False,))
    worker.start()
    assert robot.waiting.wait(10)
    assert runner.belief() == before
    with pytest.raises(RuntimeError, match="a localization is running"):
        runner.reset(None)
    robot.gate.set()
    worker.join(30)
    assert before["best_place"] is None
    assert runner.belief()["best_place"]["room"] == "kitchen"
    assert runner.reset({"seminar": 1.0})["rooms"]["seminar"] == 1.0


def test_the_service_localizes_over_zenoh_for_a_client_session(building_map):
    endpoint = free_endpoint()
    service = BusConfig(robot_id="r7", listen=(endpoint,))
    client_config = BusConfig(robot_id="r7", listen=(), connect=(endpoint,))
    robot = robot_in("seminar", 3.1, 3.3)
    with start_service(building_map[0], service, robot), open_session(client_config) as s:
        client = LocalizerClient(s, "r7", timeout_s=5.0)
        belief = client.localize(active=False)
        assert max(belief["rooms"], key=belief["rooms"].get) == "seminar"
        assert client.belief() == belief
        assert client.reset({"kitchen": 1.0})["rooms"]["kitchen"] == 1.0


def test_a_client_is_told_how_an_active_localization_went_and_the_belief_is_not(building_map):
    endpoint = free_endpoint()
    service = BusConfig(robot_id="r8", listen=(endpoint,))
    client_config = BusConfig(robot_id="r8", listen=(), connect=(endpoint,))
    with (
        start_service(building_map[0], service, robot_in("kitchen", 2.0, 3.0)),
        open_session(client_config) as s,
    ):
        client = LocalizerClient(s, "r8", timeout_s=5.0)
        reply = client.localize(active=True)
        assert reply["active"]["ended"] in ENDINGS
        assert "active" not in client.belief()


def test_the_demo_runs_end_to_end_on_a_cached_map(building_map, tmp_path, monkeypatch):
    cached = tmp_path / "building-0"
    shutil.copytree(building_map[1], cached / "dataset")  # the map is checked against it
    shutil.copy(building_map[0], cached / "map.db")
    (cached / "built-sift").touch()
    monkeypatch.setenv("TOPLOC_HOME", str(tmp_path))
    result = CliRunner().invoke(main, ["demo", "--endpoint", free_endpoint(), "--seed", "4"])
    assert result.exit_code == 0, result.output
    assert "making it again" not in result.output
    assert "3/3 client: localize, active" in result.output
    final = result.output.strip().splitlines()[-1]
    assert final.startswith("final: localized in office_b"), result.output
    assert final.endswith("the robot was kidnapped into office_b: right"), result.output


def test_a_runner_on_a_map_without_places_waits_for_the_first_ones(loaded):
    runner = LocalizationRunner(None, robot_in("kitchen", 2.0, 3.0))
    for call in (runner.belief, lambda: runner.localize(False), lambda: runner.reset(None)):
        with pytest.raises(NoPlacesYetError, match="the map has no places yet"):
            call()
    assert runner.replace_map(loaded)
    assert set(runner.belief()["rooms"]) == set(loaded.rooms)
    assert runner.localize(active=False)["best_place"]["room"] == "kitchen"


def test_serve_refuses_a_missing_map_unless_asked_to_create_it(tmp_path):
    missing = tmp_path / "new.db"
    result = CliRunner().invoke(main, ["serve", "--db", str(missing), "--robot-id", "n1"])
    assert result.exit_code == 2 and "--new-map creates it empty" in result.output
    assert not missing.exists()


def test_a_stop_that_lands_just_before_a_move_starts_still_ends_the_move(loaded):
    robot = LateStopRobot(robot_in("kitchen", 2.0, 3.0))
    runner = LocalizationRunner(Localizer(loaded), robot)

    def drive() -> None:
        with runner.driving() as held, contextlib.suppress(LocalizationStoppedError):
            held.move(0.0, 0.5)

    worker = threading.Thread(target=drive)
    worker.start()
    assert robot.moving.wait(10)
    assert runner.stop(wait_s=10.0)
    worker.join(10)
    assert robot.cut_short is True
    assert robot.stops >= 2
