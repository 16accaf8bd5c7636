"""Issue 12, "Done when": the whole loop over the P2OS protocol and Zenoh, as separate processes.

The test process runs the P2OS simulator on a pty in the rendered ``building`` world and its
simulation-only side channel (``sim/true_pose``, ``sim/kidnap``: :mod:`toploc.nodes.sim_truth`).
``toploc serve --robot p2os:PTY --source sim`` runs as a subprocess on an empty map: it drives
the pty like a real base and renders its camera at the true pose it receives over Zenoh. The
map is recorded over the bus by ``toploc map record`` subprocesses while the test drives the base
with ``base/cmd``; between rooms the base is carried (``sim/kidnap``), since driving through
the doors is not what is tested. Then the docs' client (docs/robot.md) drives it and kidnaps it
into the look-alike office_b, and ``toploc belief --active`` localizes it from another process. Only
the pty and Zenoh join the processes; the commands the simulator received are the manual's.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import zenoh
from bus_helpers import alive_nodes, free_port, wait_for

from robot.p2os_protocol import Command
from robot.p2os_sim import P2osSimulator
from robot.sim_robot import Obstacles, random_free_pose
from robot.worlds import make_world
from toploc import bus
from toploc.bus.schemas import MOVE, TRUE_POSE
from toploc.bus.session import open_when_up
from toploc.nodes.localizer import LocalizerClient
from toploc.nodes.sim_truth import SimTruthNode

REPO = Path(__file__).resolve().parents[2]
ROBOT_PAGE = REPO / "docs" / "robot.md"
WORLD = "building"
ROUTE = (("office_a", None), ("corridor", "office_a"), ("office_b", "corridor"))
"""The rooms recorded, in order, with the room each one's first panorama connects to."""
PLACES_PER_ROOM = 3
MANUAL_COMMANDS = {
    Command.OPEN,
    Command.ENABLE,
    Command.PULSE,
    Command.DHEAD,
    Command.HEAD,
    Command.VEL,
    Command.RVEL,
    Command.STOP,
    Command.CLOSE,
}
"""The commands a P2OS client sends after the SYNC0/1/2 handshake (which the simulator answers
before it records anything): the Pioneer manual's, as ``robot.p2os_base`` uses them."""


def _toploc(*args: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess[str]:
    done = subprocess.run(
        [sys.executable, "-m", "toploc", *args],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )
    assert done.returncode == 0, f"toploc {' '.join(args)}: {done.stdout}{done.stderr}"
    return done


@pytest.fixture
def simulator() -> Iterator[P2osSimulator]:
    world = make_world(WORLD)
    start = random_free_pose(Obstacles.of(world, 0.2), "office_a", np.random.default_rng(3))
    with P2osSimulator(world, start, time_scale=4.0, cycle_s=0.05, seed=3) as sim:
        yield sim


def _stop(process: subprocess.Popen[str]) -> str:
    """SIGTERM, as a user's Ctrl-C would; its output."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
    try:
        out, _ = process.communicate(timeout=15)
    except subprocess.TimeoutExpired:
        process.kill()
        out, _ = process.communicate()
    return out


def test_record_kidnap_and_localize_over_the_pty_and_zenoh(
    simulator: P2osSimulator, tmp_path: Path
) -> None:
    robot_id = f"e2e-{uuid.uuid4().hex[:8]}"
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    bus_args = ("--robot-id", robot_id, "--connect", endpoint)
    db_path = tmp_path / "map.db"
    serve = subprocess.Popen(
        [sys.executable, "-m", "toploc", "serve", "--robot", f"p2os:{simulator.port}",
         "--source", "sim", "--sim-world", WORLD, "--db", str(db_path), "--new-map",
         "--robot-id", robot_id, "--listen", endpoint],
        cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)},
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip
    # a Zenoh client of the service, as toploc sim p2os --bus is: the service routes queries
    # from its other clients (the docs') to sim/kidnap
    config = bus.BusConfig(robot_id, mode="client", listen=(), connect=(endpoint,))
    try:
        gave_up = threading.Timer(30.0, lambda: None)  # serve listens within 30 s
        gave_up.start()
        session = open_when_up(config, gave_up.finished)
        gave_up.cancel()
        assert session is not None, _stop(serve)
        with session:
            alive = lambda: {"robot", "localizer", "mapdb"} <= alive_nodes(session, robot_id)  # noqa: E731
            assert wait_for(lambda: serve.poll() is None and alive(), 30.0), _stop(serve)
            with SimTruthNode(session, robot_id, simulator, seed=5) as truth:
                localizer = LocalizerClient(session, robot_id)
                with pytest.raises(bus.BusReplyError, match="the map has no places yet"):
                    localizer.belief()
                t0 = time.monotonic()
                _record_map(session, robot_id, bus_args)
                t1 = time.monotonic()
                recorded_s = time.time()  # the map refresh after the last place comes later
                assert wait_for(lambda: _reloaded(localizer, recorded_s), 30.0)
                t2 = time.monotonic()

                exec(compile(_docs_client(robot_id, endpoint), "docs/robot.md", "exec"), {})
                assert truth.publish()["room"] == "office_b"  # the docs' drive and kidnap
                before = len(simulator.commands())
                done = _toploc("belief", "--active", "--json", *bus_args, timeout_s=240.0)
                t3 = time.monotonic()
                during = simulator.commands()[before:]
                moves = during.count(Command.DHEAD) + during.count(Command.VEL)
                print(f"record {t1 - t0:.1f} s, refresh {t2 - t1:.1f} s, localize {t3 - t2:.1f} s "
                      f"({moves} DHEAD/VEL commands)")  # fmt: skip
                belief = json.loads(done.stdout[done.stdout.index("{") :])
                true_room = truth.publish()["room"]
        print(f"true room {true_room}; final belief {belief['rooms']} ({belief['state']})")
        assert belief["top"]["room"] == true_room
        assert belief["state"] == "localized"
    finally:
        out = _stop(serve)
    assert "stopped" in out, out
    commands = simulator.commands()
    assert commands[0] == Command.OPEN and commands[-1] == Command.CLOSE
    assert set(commands) <= MANUAL_COMMANDS, sorted(set(commands) - MANUAL_COMMANDS)
    assert {Command.ENABLE, Command.PULSE, Command.DHEAD, Command.VEL, Command.STOP} <= set(
        commands
    )


def _docs_client(robot_id: str, endpoint: str) -> str:
    """The first Python client of the docs' "On a real robot" (drive, then kidnap into office_b)."""
    section = ROBOT_PAGE.read_text(encoding="utf-8").split("# On a real robot", 1)[1]
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    assert "bus.SIM_KIDNAP" in code and '"office_b"' in code
    return code.replace('"tcp/127.0.0.1:7447"', repr(endpoint)).replace('"pioneer"', repr(robot_id))


def _reloaded(localizer: LocalizerClient, after_s: float) -> bool:
    """Whether the service's belief is over the three rooms and newer than ``after_s``: the
    map refresh that follows the last ``map/add`` (``REFRESH_SETTLE_S`` after it) re-reads
    every place recorded."""
    belief = localizer.belief()
    return len(belief["rooms"]) == len(ROUTE) and belief["stamp"] > after_s


def _record_map(session: zenoh.Session, robot_id: str, bus_args: tuple[str, ...]) -> None:
    """Record ``PLACES_PER_ROOM`` panoramas in each room of ``ROUTE``, driving between them."""
    for i, (room, connect_to) in enumerate(ROUTE):
        if i:  # carried to the next room
            carry = bus.encode("kidnap", {"room": room})
            bus.request_json(session, bus.key(robot_id, bus.SIM_KIDNAP), TRUE_POSE.fields, carry)
        for k in range(PLACES_PER_ROOM):
            if k:
                cmd = bus.encode("cmd", {"turn_deg": 110.0, "forward_m": 0.6})
                moved = bus.request_json(
                    session, bus.key(robot_id, bus.BASE_CMD), MOVE.fields, cmd, timeout_s=30.0
                )
                assert math.isfinite(moved["moved_m"])
            extra = ("--connect-room", connect_to) if connect_to and not k else ()
            _toploc("map", "record", "--room", room, *extra, *bus_args)
