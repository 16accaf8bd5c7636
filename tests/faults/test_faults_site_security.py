"""Who may serve and use a site's shared map (issue 22), through a router with the docs' own
access control (docs/security.md, "A site"): real sessions on 127.0.0.1, real map files."""

from __future__ import annotations

import re
import shutil
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh
from bus_helpers import free_endpoint, wait_for

from localizer.robot_protocol import Pose2D
from mapdb.database import MapDatabase
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.worlds import make_world
from toploc import bus
from toploc.bus.clients.site_map import SiteMapClient
from toploc.bus.config import bus_config, client_bus_config
from toploc.bus.png_codec import encode_png
from toploc.nodes.mapdb import MapNode

SECURITY_PAGE = Path(__file__).resolve().parents[2] / "docs" / "security.md"
PASSWORDS = {"map-node": "map-node-secret", "robot": "robot-secret", "viewer": "viewer-secret"}
SITE = "site-1"


def panorama(room: str, x_m: float, y_m: float) -> bytes:
    """A 512 x 96 panorama of the building world at ``(x_m, y_m)`` in ``room`` (the map's size)."""
    world = make_world("building")
    pose = world.building_pose(room, Pose2D(x_m, y_m, 0.5))
    return encode_png(SimulatedRobot(world, pose, camera=PanoramaCamera(512, 96)).capture().image)


def docs_block(name: str) -> str:
    """The ```json5 block of the Security page whose first line is ``// <name>``."""
    text = SECURITY_PAGE.read_text(encoding="utf-8")
    blocks = re.findall(r"```json5\n(.*?)```", text, flags=re.DOTALL)
    (block,) = [b for b in blocks if b.startswith(f"// {name}")]
    return block


class SiteRouter:
    """The docs' router on a free port, and sessions that log in with the docs' user files."""

    def __init__(self, root: Path, access_control: bool = True) -> None:
        self.root = root
        self.endpoint = free_endpoint()
        dictionary = root / "site-credentials.txt"
        dictionary.write_text("".join(f"{u}:{p}\n" for u, p in PASSWORDS.items()))
        router_file = root / "router.json5"
        text = docs_block("router.json5")
        if not access_control:
            text = text.replace("enabled: true", "enabled: false")
        router_file.write_text(text.replace("/etc/toploc/site-credentials.txt", str(dictionary)))
        self.router = bus.open_session(bus_config("router", router_file, listen=[self.endpoint]))
        self.sessions: list[zenoh.Session] = [self.router]

    def login(self, user: str, password: str | None = None) -> zenoh.Session:
        """A session of ``user`` with the docs' file of the robot (its user and password
        replaced), connected to the router."""
        text = docs_block("robot.json5").replace('user: "robot"', f'user: "{user}"')
        text = text.replace('"robot-secret"', f'"{password or PASSWORDS.get(user, "none")}"')
        text = text.replace("tcp/site-router.local:7447", self.endpoint)
        path = self.root / f"{user}.json5"
        path.write_text(text)
        session = bus.open_session(client_bus_config(user, path, None))
        self.sessions.append(session)
        return session

    def map_node_session(self) -> zenoh.Session:
        path = self.root / "map-node.json5"
        text = docs_block("map-node.json5").replace("tcp/site-router.local:7447", self.endpoint)
        path.write_text(text.replace('"map-node-secret"', f'"{PASSWORDS["map-node"]}"'))
        session = bus.open_session(client_bus_config("maphost", path, None))
        self.sessions.append(session)
        return session

    def close(self) -> None:
        for session in reversed(self.sessions):
            session.close()


@pytest.fixture
def site(building_map, tmp_path) -> Iterator[tuple[SiteRouter, Path]]:
    db_path = tmp_path / "site.db"
    shutil.copy(building_map[0], db_path)
    router = SiteRouter(tmp_path)
    node = MapNode(router.map_node_session(), "maphost", db_path, map_id=SITE)
    yield router, db_path
    node.close()
    router.close()


def n_places(db_path: Path) -> int:
    with MapDatabase.open(db_path, readonly=True) as map_db:
        return len(map_db.places())


def test_the_docs_have_a_router_a_map_node_and_a_robot_file() -> None:
    assert "access_control" in docs_block("router.json5")
    assert 'user: "map-node"' in docs_block("map-node.json5")
    assert 'user: "robot"' in docs_block("robot.json5")


def test_a_robot_replicates_the_map_and_adds_to_it(site) -> None:
    router, db_path = site
    robot = SiteMapClient(router.login("robot"), SITE, timeout_s=2.0)
    assert wait_for(lambda: _answers(robot), 5.0)
    data, version = robot.snapshot()
    assert version == robot.version() and len(data) > 0
    before = n_places(db_path)
    assert robot.add(panorama("kitchen", 1.2, 0.8), "kitchen")["new"]
    assert n_places(db_path) == before + 1


def test_a_robots_queryable_on_a_site_maps_key_is_never_reached(site) -> None:
    router, _ = site
    impostor = router.login("robot")
    impostor.declare_queryable(
        bus.site_key("fake-site", bus.SITE_VERSION),
        lambda query: query.reply(query.key_expr, b"{}"),
    )
    robot = SiteMapClient(router.login("robot"), "fake-site", timeout_s=1.5)
    with pytest.raises(bus.BusTimeout, match="fake-site/version: no reply"):
        robot.version()


def test_without_the_access_control_the_impostor_is_reached(tmp_path) -> None:
    router = SiteRouter(tmp_path, access_control=False)
    try:
        impostor = router.login("robot")
        impostor.declare_queryable(
            bus.site_key("fake-site", bus.SITE_VERSION),
            lambda query: query.reply(
                query.key_expr,
                b'{"schema": 1, "kind": "map_version", "map_id": "fake-site", "version": 7}',
            ),
        )
        robot = SiteMapClient(router.login("viewer"), "fake-site", timeout_s=1.5)
        assert wait_for(lambda: _answers(robot), 5.0) and robot.version() == 7
    finally:
        router.close()


def test_another_user_gets_nothing_from_the_map_and_adds_nothing(site) -> None:
    router, db_path = site
    viewer = SiteMapClient(router.login("viewer"), SITE, timeout_s=1.5)
    before = n_places(db_path)
    start = time.monotonic()
    with pytest.raises(bus.BusTimeout, match="site-1/version: no reply"):
        viewer.version()
    with pytest.raises(bus.BusTimeout, match="site-1/add: no reply"):
        viewer.add_timeout_s = 1.5
        viewer.add(panorama("kitchen", 1.6, 0.8), "kitchen")
    assert time.monotonic() - start < 3.0  # denied at once, not timed out
    assert n_places(db_path) == before


def test_a_wrong_password_gets_no_session(site) -> None:
    router, _ = site
    with pytest.raises(bus.BusError, match="cannot open a Zenoh client session"):
        router.login("robot", "not-the-password")


def _answers(client: SiteMapClient) -> bool:
    try:
        client.version()
        return True
    except bus.BusError:
        return False
