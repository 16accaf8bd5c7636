"""The simulation-only side channel (``sim/true_pose``, ``sim/kidnap``) on real Zenoh sessions."""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator

import numpy as np
import pytest
from bus_helpers import ROBOT_ID, free_port, wait_for

from robot.p2os_sim import P2osSimulator
from robot.sim_robot import Obstacles, random_free_pose
from robot.worlds import make_world
from toploc import bus
from toploc.bus.schemas import TRUE_POSE
from toploc.bus.session import open_when_up
from toploc.nodes.sim_truth import SimTruthNode, TruePose, subscribe_true_pose


@pytest.fixture(scope="module")
def building():
    return make_world("building")


@pytest.fixture
def simulator(building) -> Iterator[P2osSimulator]:
    start = random_free_pose(Obstacles.of(building, 0.2), "office_a", np.random.default_rng(1))
    with P2osSimulator(building, start) as sim:
        yield sim


def _message(world: str = "building", x_m: float = 1.0) -> bytes:
    fields = {"x_m": x_m, "y_m": 3.0, "heading_deg": 90.0, "world": world, "room": None}
    return bus.encode("true_pose", {**fields, "stamp": 0.0})


def test_the_true_pose_says_why_there_is_none() -> None:
    pose = TruePose("building", ROBOT_ID, max_age_s=0.05)
    with pytest.raises(RuntimeError, match=f"no true pose on toploc/{ROBOT_ID}/sim/true_pose"):
        pose()
    pose.update(_message())
    assert pose().x_m == 1.0 and math.isclose(pose().heading_rad, math.pi / 2)
    assert wait_for(lambda: _fails(pose), 1.0)
    with pytest.raises(RuntimeError, match=r"s old \(at most 0.05 s\)"):
        pose()
    pose.update(_message("house"))
    with pytest.raises(RuntimeError, match="the simulator runs world 'house'"):
        pose()
    pose.update(b"not json")
    with pytest.raises(RuntimeError, match="not JSON"):
        pose()


def _fails(pose: TruePose) -> bool:
    try:
        pose()
    except RuntimeError:
        return True
    return False


def test_the_pose_crosses_the_bus_and_a_kidnap_moves_the_base(zbus, simulator) -> None:
    pose = TruePose("building", ROBOT_ID)
    subscriber = subscribe_true_pose(zbus.client, pose)
    with SimTruthNode(zbus.server, ROBOT_ID, simulator, period_s=0.05, seed=2):
        assert wait_for(lambda: not _fails(pose), 5.0)
        assert math.isclose(pose().x_m, simulator.true_pose.x_m)
        key = bus.key(ROBOT_ID, bus.SIM_KIDNAP)
        request = bus.encode("kidnap", {"room": "office_b"})
        moved = bus.request_json(zbus.client, key, TRUE_POSE.fields, request)
        assert moved["room"] == "office_b" and moved["world"] == "building"
        true = simulator.true_pose
        room = simulator.world.room_at(true.x_m, true.y_m)
        assert room is not None and room.name == "office_b"
        assert wait_for(lambda: math.isclose(pose().x_m, moved["x_m"]), 2.0)
        with pytest.raises(bus.BusReplyError, match="room 'attic' is not in 'building'"):
            attic = bus.encode("kidnap", {"room": "attic"})
            bus.request_json(zbus.client, key, TRUE_POSE.fields, attic)
    subscriber.undeclare()


def test_a_client_session_waits_for_the_service_until_stopped() -> None:
    nowhere = f"tcp/127.0.0.1:{free_port()}"
    config = bus.BusConfig(ROBOT_ID, mode="client", listen=(), connect=(nowhere,))
    stop = threading.Event()
    threading.Timer(0.3, stop.set).start()
    assert open_when_up(config, stop, retry_s=0.05) is None
