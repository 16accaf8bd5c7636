"""``toploc map record`` against a running service with the simulated robot: one panorama with
the odometry pose, and ``--every-m`` while a client drives the robot."""

from __future__ import annotations

import math
import shutil
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from bus_helpers import free_port, wait_for
from click.testing import CliRunner

from localizer.robot_protocol import Pose2D
from mapdb.database import MapDatabase
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.worlds import make_world
from toploc.bus import BusConfig, open_session
from toploc.cli import main
from toploc.nodes.robot import RemoteRobot
from toploc.service import Service, start_service

ROBOT_ID = "rrec"


def places_of(db_path: Path, room: str) -> list:
    with MapDatabase.open(db_path, readonly=True) as map_db:
        return [place for place in map_db.places() if place.room == room]


@pytest.fixture
def service(building_map, tmp_path) -> Iterator[tuple[Service, str, Path]]:
    """A service on a copy of the building map; the robot in the corridor looking along it."""
    db_path = tmp_path / "map.db"
    shutil.copy(building_map[0], db_path)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    world = make_world("building")
    pose = world.building_pose("corridor", Pose2D(2.0, 1.1, 0.0))
    robot = SimulatedRobot(world, pose, camera=PanoramaCamera(512, 96), seed=3)
    config = BusConfig(robot_id=ROBOT_ID, listen=(endpoint,))
    with start_service(db_path, config, robot, refresh_settle_s=0.1, recalibrate=False) as running:
        yield running, endpoint, db_path


def record(endpoint: str, *args: str):
    argv = ["map", "record", "--robot-id", ROBOT_ID, "--connect", endpoint, *args]
    return CliRunner().invoke(main, argv)


def test_record_adds_the_capture_with_the_odometry_pose_and_connects(service):
    running, endpoint, db_path = service
    before = {p.id for p in places_of(db_path, "corridor")}
    result = record(endpoint, "--room", "corridor", "--connect-room", "seminar")
    assert result.exit_code == 0, result.output
    (added,) = [p for p in places_of(db_path, "corridor") if p.id not in before]
    assert f"[1] added as place {added.id} of corridor (odometry " in result.output
    assert "the localizer uses it in 0.1 s" in result.output
    assert "corridor <-> seminar" in result.output
    assert added.x_m is not None and math.isfinite(added.x_m) and added.heading_deg is not None
    # wait for the place itself: the map/changed sample may reach the refresher after the reply
    assert wait_for(lambda: added.id in {p.id for p in running.runner.localizer.map.places}, 10)


def test_record_every_metre_while_a_client_drives(service):
    _, endpoint, db_path = service
    start = len(places_of(db_path, "hall"))

    def recorded() -> int:
        return len(places_of(db_path, "hall")) - start

    def drive() -> None:
        client = BusConfig(robot_id=ROBOT_ID, listen=(), connect=(endpoint,))
        with open_session(client) as session:
            robot = RemoteRobot(session, ROBOT_ID)
            try:
                if wait_for(lambda: recorded() >= 1, 20):
                    robot.move(0.0, 0.6)  # 0.6 m: not yet
                    robot.move(0.0, 0.6)  # 1.2 m from the first: the second
                    if wait_for(lambda: recorded() >= 2, 20):
                        robot.move(0.0, 1.1)  # the third
            finally:
                robot.close()

    driver = threading.Thread(target=drive, daemon=True)
    driver.start()
    result = record(endpoint, "--room", "hall", "--every-m", "1.0", "--count", "3", "--no-pose")
    driver.join(30)
    assert result.exit_code == 0, result.output
    assert recorded() == 3
    for n in (1, 2, 3):
        assert f"[{n}] added as place" in result.output
    assert "(no pose;" in result.output
    assert "recorded 3 panorama(s) of hall" in result.output


def test_record_errors_are_one_line(tmp_path):
    usage = CliRunner().invoke(main, ["map", "record", "--room", "kitchen", "--x-m", "1"])
    assert usage.exit_code == 2 and "give both --x-m and --y-m" in usage.output
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    nobody = record(endpoint, "--room", "kitchen", "--timeout", "1")
    assert nobody.exit_code == 1
    assert nobody.output.startswith("Error: toploc/rrec/base/odom: no reply")
    assert len(nobody.output.strip().splitlines()) == 1


def test_every_metre_with_odometry_poses_stores_the_drive_between(service):
    _, endpoint, db_path = service

    def drive() -> None:
        client = BusConfig(robot_id=ROBOT_ID, listen=(), connect=(endpoint,))
        with open_session(client) as session:
            robot = RemoteRobot(session, ROBOT_ID)
            try:
                if wait_for(lambda: len(places_of(db_path, "hall")) >= 1, 20):
                    for _ in range(3):
                        robot.move(0.0, 0.4)  # 1.2 m in three moves, each polled
            finally:
                robot.close()

    driver = threading.Thread(target=drive, daemon=True)
    driver.start()
    result = record(endpoint, "--room", "hall", "--every-m", "1.0", "--count", "2")
    driver.join(30)
    assert result.exit_code == 0, result.output
    first, second = places_of(db_path, "hall")
    assert first.leg is None
    assert second.leg is not None and second.leg.from_place == first.id
    assert f"driven from place {first.id}" in result.output
    start, end = (first.x_m, first.y_m), (second.x_m, second.y_m)
    for point in second.leg.via_xy_m:  # on the straight drive between the two
        assert math.dist(start, point) + math.dist(point, end) == pytest.approx(
            math.dist(start, end), abs=0.01
        )


def test_after_joins_the_recording_to_a_place_recorded_before(service):
    _, endpoint, db_path = service
    assert record(endpoint, "--room", "hall").exit_code == 0
    (first,) = places_of(db_path, "hall")
    with open_session(BusConfig(robot_id=ROBOT_ID, listen=(), connect=(endpoint,))) as session:
        robot = RemoteRobot(session, ROBOT_ID)
        try:
            robot.move(0.3, 0.37)  # driven on, the odometry not restarted
        finally:
            robot.close()
    result = record(endpoint, "--room", "kitchen", "--after", str(first.id))
    assert result.exit_code == 0, result.output
    (added,) = [p for p in places_of(db_path, "kitchen") if p.leg is not None]
    assert added.leg.from_place == first.id and added.leg.via_xy_m == ()


def test_after_a_place_the_map_lacks_adds_nothing_and_says_so(service):
    _, endpoint, db_path = service
    result = record(endpoint, "--room", "hall", "--after", "9999")
    assert result.exit_code == 1
    assert "field 'leg_from'" in result.output and "9999" in result.output
    assert places_of(db_path, "hall") == []


def test_after_with_a_given_pose_is_refused():
    usage = CliRunner().invoke(
        main, ["map", "record", "--room", "hall", "--no-pose", "--after", "3"]
    )
    assert usage.exit_code == 2 and "--after joins odometry poses" in usage.output
