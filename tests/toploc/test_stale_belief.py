"""The robot node goes away while the service runs: the localizer keeps serving its last belief,
marked ``stale`` with its age, and picks the robot up again when it comes back."""

from __future__ import annotations

import math
import shutil
import time

import pytest
from bus_helpers import free_port, wait_for

from localizer.belief import RoomBelief
from localizer.robot_protocol import Pose2D
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.worlds import make_world
from toploc.bus import BusConfig, open_session
from toploc.bus.messages import check_belief, mark_stale
from toploc.nodes.localizer import LocalizerClient
from toploc.nodes.robot import RobotNode
from toploc.service import start_service

ROBOT_ID = "rstale"


def kitchen_robot() -> SimulatedRobot:
    world = make_world("building")
    pose = world.building_pose("kitchen", Pose2D(2.0, 3.0, math.radians(30.0)))
    return SimulatedRobot(world, pose, camera=PanoramaCamera(512, 96), seed=9)


def test_the_belief_goes_stale_while_the_robot_is_gone_and_fresh_when_it_is_back(
    building_map, tmp_path
):
    db_path = tmp_path / "map.db"
    shutil.copy(building_map[0], db_path)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    service = BusConfig(robot_id=ROBOT_ID, listen=(endpoint,))
    base = BusConfig(robot_id=ROBOT_ID, listen=(), connect=(endpoint,))
    published: list[dict] = []
    with (
        start_service(db_path, service, None, recalibrate=False),
        open_session(base) as robot_session,
        open_session(base) as client_session,
    ):
        client = LocalizerClient(client_session, ROBOT_ID, timeout_s=10, localize_timeout_s=60)
        client.subscribe(published.append)
        with RobotNode(robot_session, ROBOT_ID, kitchen_robot()):
            belief = client.localize(active=False)
            assert "stale" not in belief and belief["top"]["room"] == "kitchen"
        assert wait_for(lambda: client.belief().get("stale") is True, 5)
        time.sleep(0.2)
        stale = client.belief()
        assert stale["rooms"] == belief["rooms"] and stale["stamp"] == belief["stamp"]
        assert stale["age_s"] >= 0.2
        assert any(p.get("stale") for p in published)
        with RobotNode(robot_session, ROBOT_ID, kitchen_robot()):
            assert wait_for(lambda: "stale" not in client.belief(), 5)
            assert wait_for(lambda: "stale" not in published[-1], 5)  # the publication may lag
            assert client.localize(active=False)["top"]["room"] == "kitchen"


def test_stale_fields_are_optional_and_checked():
    belief = RoomBelief.from_probabilities(("a", "b"), [0.7, 0.3], stamp_s=100.0).to_json()
    marked = mark_stale(belief, now_s=112.5)
    assert marked["stale"] is True and marked["age_s"] == 12.5
    assert check_belief("t", marked) == marked
    assert RoomBelief.from_json(marked).to_json() == belief  # a reader that does not know them
    assert check_belief("t", belief) == belief
    for bad in ({"stale": "yes"}, {"age_s": -1.0}, {"age_s": float("nan")}):
        with pytest.raises(ValueError, match=r"field '(stale|age_s)'"):
            check_belief("t", {**belief, **bad})
