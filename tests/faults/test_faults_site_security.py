"""Who may serve and use what on a site (issue 22), through a router with the files that
``toploc site access`` writes (docs/security.md, "A site"): one user per robot, real sessions on
127.0.0.1, real map files."""

from __future__ import annotations

import shutil
import stat
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path

import pytest
import zenoh
from bus_helpers import free_endpoint, wait_for
from click.testing import CliRunner, Result

from localizer.robot_protocol import Pose2D
from mapdb.database import MapDatabase
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.worlds import make_world
from toploc import bus
from toploc.bus.clients.homing import HomingClient
from toploc.bus.clients.site_map import SiteMapClient
from toploc.bus.config import bus_config, client_bus_config
from toploc.bus.png_codec import encode_png
from toploc.cli import main
from toploc.nodes.localizer import LocalizerClient
from toploc.nodes.mapdb import MapNode
from toploc.service import start_service

SITE = "site-1"
OTHER_SITE = "site-2"  # in the router's rules, but no map node serves it


def robot_in(room: str, x_m: float, y_m: float) -> SimulatedRobot:
    """A simulated robot of the building world at ``(x_m, y_m)`` in ``room``, its camera the
    map's (512 x 96)."""
    pose = make_world("building").building_pose(room, Pose2D(x_m, y_m, 0.5))
    return SimulatedRobot(make_world("building"), pose, camera=PanoramaCamera(512, 96))


def panorama(room: str, x_m: float, y_m: float) -> bytes:
    """A panorama of :func:`robot_in`'s robot."""
    return encode_png(robot_in(room, x_m, y_m).capture().image)


def site_access(out: Path, endpoint: str, *args: str) -> Result:
    """``toploc site access`` for the test's site (robots and users in ``args``) into ``out``."""
    return CliRunner().invoke(
        main,
        ["site", "access", "--map-id", SITE, "--map-id", OTHER_SITE, "--router", endpoint,
         "--listen", endpoint, "--out", str(out), *args],
    )  # fmt: skip


class SiteRouter:
    """A router on a free port with the files of ``toploc site access`` for robots r1 and r2,
    operator ``ops`` and viewer ``watcher``; sessions log in with each user's own file."""

    def __init__(self, root: Path, access_control: bool = True) -> None:
        self.files = root / "site-access"
        self.endpoint = free_endpoint()
        result = site_access(
            self.files, self.endpoint, "--robot", "r1", "--robot", "r2", "--operator", "ops",
            "--viewer", "watcher",
        )  # fmt: skip
        assert result.exit_code == 0, result.output
        router_file = self.files / "router.json5"
        if not access_control:
            text = router_file.read_text().replace('"enabled": true', '"enabled": false')
            router_file.write_text(text)
        self.router = bus.open_session(bus_config("router", router_file))
        self.sessions: list[zenoh.Session] = [self.router]

    def login(self, user: str) -> zenoh.Session:
        """A session of ``user`` with its own file, connected to the router."""
        session = bus.open_session(self.config(user))
        self.sessions.append(session)
        return session

    def config(self, user: str) -> bus.BusConfig:
        return client_bus_config(user, self.files / f"{user}.json5")

    def close(self) -> None:
        for session in reversed(self.sessions):
            session.close()


@pytest.fixture
def site(building_map, tmp_path) -> Iterator[tuple[SiteRouter, Path]]:
    db_path = tmp_path / "site.db"
    shutil.copy(building_map[0], db_path)
    router = SiteRouter(tmp_path)
    node = MapNode(router.login("map-node"), "maphost", db_path, map_id=SITE)
    yield router, db_path
    node.close()
    router.close()


def n_places(db_path: Path) -> int:
    with MapDatabase.open(db_path, readonly=True) as map_db:
        return len(map_db.places())


def serve_belief(session: zenoh.Session, key_expr: str) -> None:
    """A queryable on ``key_expr`` answering with a belief-shaped reply."""
    session.declare_queryable(key_expr, lambda query: query.reply(query.key_expr, b"{}"))


def reached(session: zenoh.Session, key_expr: str, timeout_s: float = 1.0) -> bool:
    """Whether a query on ``key_expr`` gets any reply within ``timeout_s``."""
    return any(reply.ok is not None for reply in session.get(key_expr, timeout=timeout_s))


def test_each_user_gets_a_file_and_a_password_of_its_own(tmp_path) -> None:
    result = site_access(tmp_path, "tcp/site-router.local:7447", "--robot", "r1", "--robot", "r2")
    assert result.exit_code == 0, result.output
    credentials = (tmp_path / "site-credentials.txt").read_text().splitlines()
    assert [line.split(":")[0] for line in credentials] == ["map-node", "r1", "r2"]
    assert len({line.split(":")[1] for line in credentials}) == 3
    for name in ("router.json5", "site-credentials.txt", "map-node.json5", "r1.json5", "r2.json5"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o600, name


def test_running_again_adds_a_robot_and_keeps_the_passwords(tmp_path) -> None:
    endpoint = "tcp/site-router.local:7447"
    assert site_access(tmp_path, endpoint, "--robot", "r1").exit_code == 0
    before = (tmp_path / "r1.json5").read_text()
    result = site_access(tmp_path, endpoint, "--robot", "r1", "--robot", "r2")
    assert result.exit_code == 0 and "(new: r2)" in result.output
    assert (tmp_path / "r1.json5").read_text() == before
    assert '"user": "r2"' in (tmp_path / "r2.json5").read_text()


def test_a_robot_left_out_of_a_second_run_must_be_dropped_by_name(tmp_path) -> None:
    endpoint = "tcp/site-router.local:7447"
    assert site_access(tmp_path, endpoint, "--robot", "r1", "--robot", "r2").exit_code == 0
    credentials = (tmp_path / "site-credentials.txt").read_text()
    forgot = site_access(tmp_path, endpoint, "--robot", "r1")
    assert forgot.exit_code == 2 and "r2 in" in forgot.output and "--drop" in forgot.output
    assert (tmp_path / "site-credentials.txt").read_text() == credentials
    dropped = site_access(tmp_path, endpoint, "--robot", "r1", "--drop", "r2")
    assert dropped.exit_code == 0 and "dropped: r2" in dropped.output
    assert "r2:" not in (tmp_path / "site-credentials.txt").read_text()


def test_a_robot_id_that_cannot_be_a_user_name_is_refused(tmp_path) -> None:
    result = site_access(tmp_path, "tcp/site-router.local:7447", "--robot", "r:1")
    assert result.exit_code == 2 and "'r:1'" in result.output
    assert not (tmp_path / "site-credentials.txt").exists()


def test_a_damaged_credentials_file_is_named_and_kept(tmp_path) -> None:
    (tmp_path / "site-credentials.txt").write_text("map-node:secret\nr1 no colon\n")
    result = site_access(tmp_path, "tcp/site-router.local:7447", "--robot", "r1")
    assert result.exit_code == 1 and "site-credentials.txt: line 2" in result.output
    assert (tmp_path / "site-credentials.txt").read_text() == "map-node:secret\nr1 no colon\n"


def test_a_router_endpoint_without_a_port_is_refused(tmp_path) -> None:
    result = CliRunner().invoke(
        main, ["site", "access", "--map-id", SITE, "--robot", "r1", "--router", "site-router"]
    )
    assert result.exit_code == 2 and "'--router'" in result.output


def test_a_robot_service_replicates_and_localizes_through_the_router(site, tmp_path) -> None:
    router, _ = site
    with ExitStack() as stack:
        stack.enter_context(
            start_service(
                tmp_path / "r1.db", router.config("r1"), robot_in("kitchen", 2.2, 2.9),
                recalibrate=False, map_from=SITE,
            )
        )  # fmt: skip
        operator = LocalizerClient(router.login("ops"), "r1", timeout_s=3.0)
        assert wait_for(lambda: reached(operator.session, "toploc/r1/localizer/belief"), 5.0)
        assert operator.localize()["state"] in ("localized", "ambiguous", "lost")


def test_a_robot_adds_to_the_site_map(site) -> None:
    router, db_path = site
    robot = SiteMapClient(router.login("r1"), SITE, timeout_s=2.0)
    assert wait_for(lambda: _answers(robot), 5.0)
    before = n_places(db_path)
    assert robot.add(panorama("kitchen", 1.2, 0.8), "kitchen")["new"]
    assert n_places(db_path) == before + 1


def test_a_robot_serves_its_own_keys(site) -> None:
    router, _ = site
    serve_belief(router.login("r2"), "toploc/r2/localizer/belief")
    ops = router.login("ops")
    assert wait_for(lambda: reached(ops, "toploc/r2/localizer/belief"), 5.0)


def test_a_robot_cannot_serve_another_robots_keys(site) -> None:
    router, _ = site
    serve_belief(router.login("r2"), "toploc/r2/localizer/reset")
    serve_belief(router.login("r1"), "toploc/r2/localizer/belief")
    operator = router.login("ops")
    assert wait_for(lambda: reached(operator, "toploc/r2/localizer/reset"), 5.0)
    assert not reached(operator, "toploc/r2/localizer/belief", timeout_s=1.5)


def test_a_robot_cannot_serve_a_site_maps_keys(site) -> None:
    router, _ = site
    serve_belief(router.login("r1"), bus.site_key(OTHER_SITE, bus.SITE_VERSION))
    other = SiteMapClient(router.login("r2"), OTHER_SITE, timeout_s=1.5)
    with pytest.raises(bus.BusTimeout, match="site-2/version: no reply"):
        other.version()


def test_without_the_access_control_the_impostor_is_reached(tmp_path) -> None:
    router = SiteRouter(tmp_path, access_control=False)
    try:
        serve_belief(router.login("r1"), "toploc/r2/localizer/belief")
        ops = router.login("ops")
        assert wait_for(lambda: reached(ops, "toploc/r2/localizer/belief"), 5.0)
    finally:
        router.close()


def test_a_viewer_reads_a_robots_belief(site) -> None:
    router, _ = site
    serve_belief(router.login("r1"), "toploc/r1/localizer/belief")
    watcher = router.login("watcher")
    assert wait_for(lambda: reached(watcher, "toploc/r1/localizer/belief"), 5.0)


def test_a_viewer_cannot_drive_a_robot(site) -> None:
    router, _ = site
    serve_belief(router.login("r1"), "toploc/r1/homing/goal")
    ops = router.login("ops")
    assert wait_for(lambda: reached(ops, "toploc/r1/homing/goal"), 5.0)
    viewer = HomingClient(router.login("watcher"), "r1", timeout_s=1.5)
    with pytest.raises(bus.BusTimeout, match="r1/homing/goal: no reply"):
        viewer.goal(3, timeout_s=0.0)


def test_a_viewer_adds_nothing_to_the_map(site) -> None:
    router, db_path = site
    viewer = SiteMapClient(router.login("watcher"), SITE, timeout_s=1.5)
    assert wait_for(lambda: _answers(viewer), 5.0)  # it reads the map's version
    before = n_places(db_path)
    viewer.add_timeout_s = 1.5
    with pytest.raises(bus.BusTimeout, match="site-1/add: no reply"):
        viewer.add(panorama("kitchen", 1.6, 0.8), "kitchen")
    assert n_places(db_path) == before


def test_a_wrong_password_gets_no_session(site) -> None:
    router, _ = site
    path = router.files / "r1.json5"
    text = path.read_text()
    password = text.split('"password": "')[1].split('"')[0]
    path.write_text(text.replace(password, "not-the-password"))
    with pytest.raises(bus.BusError, match="cannot open a Zenoh client session"):
        router.login("r1")


def _answers(client: SiteMapClient) -> bool:
    try:
        client.version()
        return True
    except bus.BusError:
        return False
