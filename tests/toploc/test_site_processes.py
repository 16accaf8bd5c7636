"""Issue 22's "Done when": a router, a site map node and three robot services, each a process of
its own on 127.0.0.1 (the commands of docs/site.md). All three robots record (``map/add``) and
localize on the one map; the router is killed and restarted; the map node is killed with -9
during adds and restarted. Afterwards every place whose add was answered is in the map, and
every robot's replica equals the map (same version, same rows)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from bus_helpers import free_endpoint, wait_for
from test_map_bus import panorama

from mapdb.database import MapDatabase
from mapdb.replica import read_snapshot
from toploc import bus
from toploc.bus import BusConfig, open_session
from toploc.bus.clients.site_map import SiteMapClient
from toploc.nodes.localizer import LocalizerClient
from toploc.nodes.mapdb import MapClient

REPO = Path(__file__).resolve().parents[2]
SITE = "site-1"
ROBOTS = ("r1", "r2", "r3")
ROUTER = """
import sys
from toploc import bus
from toploc.commands.options import stop_on_signals
with stop_on_signals() as stop:  # waits in slices: a signal to a Zenoh thread still stops it
    session = bus.open_session(bus.BusConfig("router", "router", listen=(sys.argv[1],)))
    print("up", flush=True)
    stop.wait_for_signal()
    session.close()
"""

pytestmark = pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="needs kill -9")


class Processes:
    """The site's processes, each started by name; stopped (SIGTERM, then kill) at the end."""

    def __init__(self, root: Path, endpoint: str) -> None:
        self.root, self.endpoint = root, endpoint
        self.running: dict[str, subprocess.Popen[str]] = {}
        self.env = {**os.environ, "PYTHONPATH": str(REPO), "TOPLOC_HOME": str(root / "home")}

    def start(self, name: str, args: list[str]) -> None:
        log = (self.root / f"{name}.log").open("a")
        self.running[name] = subprocess.Popen(
            [sys.executable, *args], stdout=log, stderr=subprocess.STDOUT, text=True,
            env=self.env, cwd=REPO,
        )  # fmt: skip

    def router(self) -> None:
        ups = self.log("router").count("up") if self._has_log("router") else 0
        self.start("router", ["-c", ROUTER, self.endpoint])
        assert wait_for(lambda: self.log("router").count("up") > ups, 20.0), self.log("router")

    def _has_log(self, name: str) -> bool:
        return (self.root / f"{name}.log").exists()

    def map_node(self, db_path: Path) -> None:
        self.start("map", ["-m", "toploc", "node", "map", "--db", str(db_path), "--map-id", SITE,
                           "--robot-id", "maphost", "--connect", self.endpoint,
                           "--no-calibrate"])  # fmt: skip

    def robot(self, robot_id: str) -> None:
        self.start(robot_id, [
            "-m", "toploc", "serve", "--map-from", SITE, "--db", str(self.root / f"{robot_id}.db"),
            "--robot-id", robot_id, "--connect", self.endpoint, "--sim-room", "kitchen",
        ])  # fmt: skip

    def kill(self, name: str) -> None:
        process = self.running.pop(name)
        process.send_signal(signal.SIGKILL)
        process.wait(10)

    def stop_all(self) -> None:
        for process in self.running.values():
            process.send_signal(signal.SIGTERM)
        for name, process in self.running.items():
            try:
                process.wait(15)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait(5)
                pytest.fail(f"{name} did not stop on SIGTERM")

    def log(self, name: str) -> str:
        return (self.root / f"{name}.log").read_text()


@pytest.fixture
def site(building_map, tmp_path) -> Iterator[tuple[Processes, Path]]:
    db_path = tmp_path / "site.db"
    shutil.copy(building_map[0], db_path)
    processes = Processes(tmp_path, free_endpoint())
    try:
        yield processes, db_path
    finally:
        processes.stop_all()


def answers(client: SiteMapClient) -> bool:
    try:
        client.version()
        return True
    except bus.BusError:
        return False


def localizes(session, robot_id: str) -> bool:
    try:
        return bool(LocalizerClient(session, robot_id, timeout_s=2.0).belief())
    except bus.BusError:
        return False


def replica_equals_map(replica: Path, db_path: Path) -> bool:
    if not replica.exists():
        return False
    with (
        MapDatabase.open(replica, readonly=True) as copy,
        MapDatabase.open(db_path, readonly=True) as original,
    ):
        return read_snapshot(copy) == read_snapshot(original)


def add_all(session, images: dict[str, bytes], answered: list[int]) -> None:
    """Each robot adds its image through its own ``map/add`` at once; the answered ones'
    place ids go into ``answered`` (an add lost with the map node raises nothing here)."""

    def add(robot_id: str) -> None:
        try:
            reply = MapClient(session, robot_id, add_timeout_s=20.0).add(
                images[robot_id], "kitchen"
            )
            answered.append(int(reply["place_id"]))
        except bus.BusError:
            pass  # the map node was killed under it

    threads = [threading.Thread(target=add, args=(robot_id,)) for robot_id in images]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(30)


def test_three_robots_one_map_through_a_router_with_kills(site) -> None:
    processes, db_path = site
    processes.router()
    processes.map_node(db_path)
    config = BusConfig("tester", "client", listen=(), connect=(processes.endpoint,))
    answered: list[int] = []
    positions = iter([(x, y) for y in (0.8, 3.2) for x in (0.8, 1.2, 1.6, 2.0, 2.4, 2.8)])

    def images() -> dict[str, bytes]:
        return {r: panorama("kitchen", *next(positions)) for r in ROBOTS}

    with open_session(config) as session:
        site_map = SiteMapClient(session, SITE, timeout_s=2.0)
        assert wait_for(lambda: answers(site_map), 30.0), processes.log("map")
        for robot_id in ROBOTS:
            processes.robot(robot_id)
        for robot_id in ROBOTS:
            assert wait_for(lambda r=robot_id: localizes(session, r), 60.0), processes.log(robot_id)

        add_all(session, images(), answered)  # all three record at once
        assert len(answered) == 3
        for robot_id in ROBOTS:
            belief = LocalizerClient(session, robot_id, localize_timeout_s=30.0).localize()
            assert belief["rooms"] and belief["map_age_s"] is not None

        processes.kill("router")  # the site's router dies; robots and map lose each other
        processes.router()
        assert wait_for(lambda: answers(site_map), 30.0)

        adding = threading.Thread(target=add_all, args=(session, images(), answered))
        adding.start()  # the map node is killed with -9 while the three adds run
        assert wait_for(lambda: "map add" in processes.log("map") or not adding.is_alive(), 20.0)
        processes.kill("map")
        adding.join(40)
        processes.map_node(db_path)
        assert wait_for(lambda: answers(site_map), 30.0), processes.log("map")
        add_all(session, images(), answered)  # and the robots record on

        with MapDatabase.open(db_path, readonly=True) as map_db:
            held = {place.id for place in map_db.places()}
            version = map_db.map_version()
            half_places = map_db.db.execute(
                "SELECT COUNT(*) FROM places p WHERE NOT EXISTS "
                "(SELECT 1 FROM fingerprints f WHERE f.place_id = p.id)"
            ).fetchone()[0]
            logged = map_db.db.execute("SELECT COUNT(*) FROM changes").fetchone()[0]
        assert half_places == 0 and logged == version  # whole places, one version each write
        assert len(answered) >= 6 and set(answered) <= held  # nothing answered was lost
        for robot_id in ROBOTS:
            replica = processes.root / f"{robot_id}.db"
            assert wait_for(lambda r=replica: replica_equals_map(r, db_path), 30.0), robot_id
            belief = LocalizerClient(session, robot_id, timeout_s=3.0).belief()
            assert belief["map_age_s"] is not None and belief["map_age_s"] < 10.0
        with MapDatabase.open(processes.root / "r1.db", readonly=True) as replica_db:
            assert replica_db.map_version() == version
