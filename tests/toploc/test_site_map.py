"""One site map, several robots (issue 22): a router session on 127.0.0.1, the site map's node
and robot services on replicas of their own, all in this process on real Zenoh sessions and real
SQLite files. The same in separate processes, with kills: test_site_processes.py."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import zenoh
from bus_helpers import free_endpoint, make_belief, wait_for
from click.testing import CliRunner
from mapdb_helpers import make_fingerprint, new_place
from test_map_bus import panorama, robot_in
from test_node_commands import nodes

from localizer.belief import RoomBelief
from mapdb.database import MapDatabase
from mapdb.errors import MapDatabaseError, ReplicaError
from mapdb.replica import read_changes, read_snapshot, replica_state, write_snapshot
from mapdb.replication import encode_changes, encode_snapshot, sha256_hex, split_chunks
from toploc import bus
from toploc.bus import BusConfig, open_session
from toploc.bus.clients.site_map import SiteMapClient
from toploc.bus.messages import check_belief
from toploc.bus.png_codec import encode_png
from toploc.bus.schemas import CHANGED, CHANGES_BATCH, MAP_VERSION, SNAPSHOT_CHUNK
from toploc.cli import main
from toploc.nodes.localizer import LocalizerClient
from toploc.nodes.mapdb import MapClient, MapNode, check_site_map
from toploc.nodes.robot import RobotNode
from toploc.replication import MapReplicator
from toploc.service import start_service

SITE = "site-1"


def client_config(endpoint: str, robot_id: str = "viewer") -> BusConfig:
    return BusConfig(robot_id, "client", listen=(), connect=(endpoint,))


class Site:
    """A router on a free port and the site map's node (a copy of the building map) behind it;
    :meth:`router_down` and :meth:`router_up` stop and start the router."""

    def __init__(self, building_map: Path, root: Path) -> None:
        self.endpoint = free_endpoint()
        self.db_path = root / "site.db"
        shutil.copy(building_map, self.db_path)
        self.router: zenoh.Session | None = None
        self.router_up()
        self.session = open_session(client_config(self.endpoint, "maphost"))
        self.node = MapNode(self.session, "maphost", self.db_path, map_id=SITE, chunk_bytes=50_000)
        self.viewer = open_session(client_config(self.endpoint))
        self.client = SiteMapClient(self.viewer, SITE)
        assert wait_for(self._answers, 5.0)

    def _answers(self) -> bool:
        try:
            self.client.version()
            return True
        except bus.BusError:
            return False

    def version(self) -> int:
        with MapDatabase.open(self.db_path, readonly=True) as map_db:
            return map_db.map_version()

    def router_up(self) -> None:
        self.router = open_session(BusConfig("router", "router", listen=(self.endpoint,)))

    def router_down(self) -> None:
        assert self.router is not None
        self.router.close()
        self.router = None

    def close(self) -> None:
        self.node.close()
        for session in (self.viewer, self.session, self.router):
            if session is not None:
                session.close()


@pytest.fixture
def site(building_map, tmp_path) -> Iterator[Site]:
    running = Site(building_map[0], tmp_path)
    yield running
    running.close()


def robot_service(stack: ExitStack, site: Site, robot_id: str, replica: Path):
    """A robot service of ``robot_id`` on its replica of the site map, through the router."""
    robot = robot_in("kitchen", 2.2, 2.9, 75.0)
    return stack.enter_context(
        start_service(
            replica, client_config(site.endpoint, robot_id), robot, refresh_settle_s=0.1,
            recalibrate=False, map_from=SITE,
        )
    )  # fmt: skip


def same_rows(replica: Path, site: Site) -> bool:
    with (
        MapDatabase.open(replica, readonly=True) as copy,
        MapDatabase.open(site.db_path, readonly=True) as original,
    ):
        return read_snapshot(copy) == read_snapshot(original)


def test_a_robot_starts_on_a_replica_equal_to_the_map_sent_in_chunks(site, tmp_path) -> None:
    replica = tmp_path / "r1.db"
    with ExitStack() as stack:
        robot_service(stack, site, "r1", replica)
        assert same_rows(replica, site)
        with open_session(client_config(site.endpoint)) as session:
            belief = LocalizerClient(session, "r1", timeout_s=3.0).belief()
        assert 0 <= belief["map_age_s"] < 5.0


def test_a_place_one_robot_adds_reaches_the_map_and_every_robots_replica(site, tmp_path) -> None:
    replicas = [tmp_path / "r1.db", tmp_path / "r2.db"]
    with ExitStack() as stack:
        services = [robot_service(stack, site, f"r{i + 1}", p) for i, p in enumerate(replicas)]
        before = site.version()
        reply = MapClient(site.viewer, "r1").add(panorama("kitchen", 1.0, 1.0), "kitchen", 1.0, 1.0)
        assert reply["new"] and site.version() == before + 1
        for replica, service in zip(replicas, services, strict=True):
            assert wait_for(lambda r=replica: same_rows(r, site), 10.0)
            assert service.refresher.wait_idle(10.0)
            loaded = service.runner.localizer
            assert loaded is not None and reply["place_id"] in loaded.map.table.place_ids


def test_a_localizer_node_keeps_a_replica_of_its_own_beside_the_robots_node(
    site, tmp_path, monkeypatch
) -> None:
    monkeypatch.setenv("TOPLOC_HOME", str(tmp_path / "home"))  # where the replica goes
    replica = tmp_path / "home" / "replicas" / f"{SITE}.db"
    robot = robot_in("kitchen", 2.2, 2.9, 75.0)
    with ExitStack() as stack:
        session = stack.enter_context(open_session(client_config(site.endpoint, "r1")))
        stack.enter_context(RobotNode(session, "r1", robot))  # the robot's own process
        (node,) = stack.enter_context(
            nodes(("localizer", "--map-from", SITE, "--robot-id", "r1", "--connect", site.endpoint))
        )
        assert f"a replica of site map {SITE} at {replica}" in node.output[-1]
        assert same_rows(replica, site)
        localizer = LocalizerClient(site.viewer, "r1", timeout_s=5.0, localize_timeout_s=30.0)
        belief = localizer.localize()
        assert belief["top"]["room"] == "kitchen" and 0 <= belief["map_age_s"] < 5.0
        added = site.client.add(encode_png(robot.capture().image), "annex")  # another robot's add
        assert wait_for(lambda: same_rows(replica, site), 10.0)
        assert wait_for(
            lambda: localizer.localize()["best_place"]["place_id"] == added["place_id"], 25.0
        ), node.output
        assert "annex" in localizer.belief()["rooms"]
    assert node.process.returncode == 0 and node.output[-1] == "stopped", node.output


def test_offline_the_robot_localizes_from_its_replica_and_catches_up_after(site, tmp_path) -> None:
    replica = tmp_path / "r1.db"
    rng = np.random.default_rng(3)
    with ExitStack() as stack:
        service = robot_service(stack, site, "r1", replica)
        site.router_down()
        with MapDatabase.open(site.db_path) as map_db:  # the map host records meanwhile
            place = new_place("kitchen", 999)
            map_db.add_place(place, [make_fingerprint(rng, n=30)])
        replicator = service.replicator
        assert replicator is not None
        belief = service.runner.localize(active=False)
        assert belief["rooms"]  # the replica is enough to localize
        assert wait_for(lambda: (replicator.map_age_s() or 0) > 3.0, 8.0)  # not confirmed
        assert not same_rows(replica, site)
        site.router_up()
        assert wait_for(lambda: same_rows(replica, site), 15.0)
        assert (replicator.map_age_s() or 99) < 3.0


def test_the_belief_says_how_old_the_replica_is_while_the_link_is_down(site, tmp_path) -> None:
    replica = tmp_path / "r1.db"
    with ExitStack() as stack:
        robot_service(stack, site, "r1", replica)
        robot = stack.enter_context(open_session(client_config(site.endpoint)))
        site.router_down()
        site.router_up()  # the robot's link went; its local clients see it again before the map
        localizer = LocalizerClient(robot, "r1", timeout_s=3.0)
        assert wait_for(lambda: _belief_age(localizer) is not None, 10.0)
        assert wait_for(lambda: (_belief_age(localizer) or 99) < 2.5, 10.0)  # caught up


def _belief_age(localizer: LocalizerClient) -> float | None:
    try:
        return localizer.belief().get("map_age_s")
    except bus.BusError:
        return None


def test_a_replica_of_another_map_is_refused_and_left_as_it_was(site, tmp_path) -> None:
    replica = tmp_path / "r1.db"
    other = tmp_path / "other.db"
    with MapDatabase.open(other) as map_db:
        map_db.add_place(new_place("hall", 1), [make_fingerprint(np.random.default_rng(1))])
        write_snapshot(replica, encode_snapshot(read_snapshot(map_db)), str(map_db.map_id()))
    before = replica.read_bytes()
    refused = pytest.raises(ReplicaError, match=r"is of map 'map-.*', not 'site-1': refused")
    with ExitStack() as stack, refused:
        robot_service(stack, site, "r1", replica)
    assert replica.read_bytes() == before


def test_a_replica_ahead_of_the_map_node_is_refused(site, tmp_path) -> None:
    replica = tmp_path / "r1.db"
    with MapDatabase.open(site.db_path, readonly=True) as map_db:
        snapshot = read_snapshot(map_db)
    ahead = encode_snapshot(type(snapshot)(snapshot.map_id, snapshot.version + 5, snapshot.rows))
    write_snapshot(replica, ahead, SITE)
    with ExitStack() as stack, pytest.raises(ReplicaError, match="ahead of map 'site-1'"):
        robot_service(stack, site, "r1", replica)
    assert replica_state(replica).version == snapshot.version + 5  # type: ignore[union-attr]


def test_changes_after_an_unknown_version_are_an_error_reply(site) -> None:
    with pytest.raises(bus.BusReplyError, match=r"site-1/changes: map site-1 has no version 999"):
        site.client.changes(999)


def test_robots_add_through_their_own_keys_or_the_site_keys(site, tmp_path) -> None:
    with ExitStack() as stack:
        robot_service(stack, site, "r1", tmp_path / "r1.db")
        image = encode_png(robot_in("office_a", 1.5, 1.5).capture().image)
        assert site.client.add(image, "office_a", 1.5, 1.5)["new"]
        again = MapClient(site.viewer, "r1").add(image, "office_a", 1.5, 1.5)
        assert not again["new"]  # the same place, through the robot's key


def test_a_site_robot_says_on_its_own_keys_when_its_replica_takes_other_robots_places(
    site, tmp_path
) -> None:
    heard: list[dict] = []
    with ExitStack() as stack:
        robot_service(stack, site, "r1", tmp_path / "r1.db")
        stack.callback(
            bus.subscribe(
                site.viewer, bus.key("r1", bus.MAP_CHANGED), CHANGED.decode, heard.append
            ).undeclare
        )
        image = encode_png(robot_in("office_a", 1.5, 1.5).capture().image)
        assert site.client.add(image, "office_a", 1.5, 1.5)["new"]  # another robot's add
        assert wait_for(lambda: any(m["version"] == site.version() for m in heard), 10.0)
    (message,) = heard
    assert message["what"] == "replica" and message["map_id"] == SITE


def test_a_map_named_once_keeps_its_name(tmp_path) -> None:
    db_path = tmp_path / "site.db"
    MapDatabase.open(db_path).close()
    check_site_map(db_path, "site-1")  # its automatic id gives way to the first name
    check_site_map(db_path, "site-1")
    with pytest.raises(MapDatabaseError, match="is site map 'site-1', not 'site-2': serve it"):
        check_site_map(db_path, "site-2")


def test_map_ids_and_flags_that_cannot_be_are_one_line_errors(tmp_path) -> None:
    db = str(tmp_path / "site.db")
    bad_id = CliRunner().invoke(main, ["node", "map", "--db", db, "--new-map", "--map-id", "a/b"])
    assert bad_id.exit_code == 2 and "map id must be a non-empty key chunk" in bad_id.output
    both = CliRunner().invoke(main, ["serve", "--map-from", "site-1", "--new-map", "--db", db])
    assert both.exit_code == 2 and "--new-map and --map-from" in both.output
    robot = CliRunner().invoke(main, ["belief", "--robot-id", "map"])
    assert robot.exit_code != 0 and "robot id 'map' is taken" in robot.output


def test_map_age_is_an_optional_field_of_the_belief() -> None:
    belief = {**make_belief({"kitchen": 0.7, "office_a": 0.3}), "map_age_s": 1.5}
    assert check_belief("test", belief)["map_age_s"] == 1.5
    assert RoomBelief.from_json(belief).rooms == ("kitchen", "office_a")  # one that ignores it
    with pytest.raises(bus.BusMessageError, match="map_age_s"):
        check_belief("test", {**belief, "map_age_s": "old"})


class FakeSiteNode:
    """Raw queryables of site map ``SITE`` on ``session`` answering with what a test gives:
    ``version`` always ``version``, ``snapshot`` the given replies, ``changes`` the given one."""

    def __init__(self, session: zenoh.Session, version: int) -> None:
        self.snapshot_replies: list[tuple[bytes, bytes]] = []
        self.changes_reply: tuple[bytes, bytes] = (b"", b"")
        head = MAP_VERSION.encode({"map_id": SITE, "version": version})
        self.entities = [
            bus.serve(session, bus.site_key(SITE, bus.SITE_VERSION), lambda _p: bus.Reply(head)),
            bus.serve_replies(
                session, bus.site_key(SITE, bus.SITE_SNAPSHOT),
                lambda _p: [bus.Reply(data, att) for data, att in self.snapshot_replies],
            ),
            bus.serve(
                session, bus.site_key(SITE, bus.SITE_CHANGES),
                lambda _p: bus.Reply(*self.changes_reply),
            ),
        ]  # fmt: skip

    def wait_reachable(self, session: zenoh.Session) -> None:
        """Wait until ``session`` gets this node's answer (its queryables reached the router)."""

        def answers() -> bool:
            replies = session.get(bus.site_key(SITE, bus.SITE_VERSION), timeout=1.0)
            return any(reply.ok is not None for reply in replies)

        assert wait_for(answers, 5), "the site node's queryables never reached the client"

    def close(self) -> None:
        bus.undeclare_all(self.entities)


def small_map(path: Path, n: int) -> MapDatabase:
    map_db = MapDatabase.open(path)
    map_db.set_map_id(SITE)
    rng = np.random.default_rng(5)
    for i in range(n):
        map_db.add_place(new_place("hall", i), [make_fingerprint(rng)])
    return map_db


def test_a_truncated_snapshot_on_the_bus_is_refused_and_no_replica_made(zbus, tmp_path) -> None:
    with small_map(tmp_path / "site.db", 3) as map_db:
        data = encode_snapshot(read_snapshot(map_db))
    node = FakeSiteNode(zbus.server, version=3)
    node.wait_reachable(zbus.client)
    chunks = split_chunks(data, 1000)
    head = {"map_id": SITE, "version": 3, "n_chunks": len(chunks), "total_bytes": len(data),
            "sha256": sha256_hex(data)}  # fmt: skip
    node.snapshot_replies = [
        (chunk, SNAPSHOT_CHUNK.encode({**head, "index": i}))
        for i, chunk in enumerate(chunks)
        if i != 1  # one chunk lost on the way
    ]
    replicator = MapReplicator(zbus.client, SITE, tmp_path / "replica.db", timeout_s=10.0)
    try:
        with pytest.raises(bus.BusMessageError, match=r"snapshot is truncated: 1 of \d+ chunks"):
            replicator.sync()
        assert not (tmp_path / "replica.db").exists()
    finally:
        replicator.close()
        node.close()


def test_changes_whose_fingerprint_does_not_decode_leave_the_replica_as_it_was(
    zbus, tmp_path
) -> None:
    replica = tmp_path / "replica.db"
    with small_map(tmp_path / "site.db", 2) as map_db:
        write_snapshot(replica, encode_snapshot(read_snapshot(map_db)), SITE)
        map_db.add_place(new_place("hall", 7), [make_fingerprint(np.random.default_rng(9))])
        changes = read_changes(map_db, 2)
    place, fingerprint = changes[0].rows.places, changes[0].rows.fingerprints[0]
    broken = (*fingerprint[:8], fingerprint[8][:-4], *fingerprint[9:])  # 4 bytes short
    rows = replace(changes[0].rows, places=place, fingerprints=(broken,))
    node = FakeSiteNode(zbus.server, version=3)
    node.wait_reachable(zbus.client)
    node.changes_reply = (
        encode_changes(SITE, [replace(changes[0], rows=rows)]),
        CHANGES_BATCH.encode({"map_id": SITE, "version": 3, "more": False}),
    )
    before = replica.read_bytes()
    replicator = MapReplicator(zbus.client, SITE, replica, timeout_s=10.0)
    try:
        with pytest.raises(ReplicaError, match=r"changes refused: change 3: .*descriptors blob"):
            replicator.sync()
        assert replica.read_bytes() == before and replicator.map_age_s() is None
    finally:
        replicator.close()
        node.close()


def test_a_map_host_that_is_a_robot_too_sees_the_places_other_robots_add(site, tmp_path) -> None:
    host_map = tmp_path / "host.db"
    shutil.copy(site.db_path, host_map)
    with MapDatabase.open(host_map) as map_db:
        map_db.set_map_id("site-2")
    with ExitStack() as stack:
        host = stack.enter_context(start_service(
            host_map, client_config(site.endpoint, "host"), robot_in("kitchen", 2.2, 2.9),
            refresh_settle_s=0.1, recalibrate=False, map_id="site-2",
        ))  # fmt: skip
        other = stack.enter_context(open_session(client_config(site.endpoint, "r9")))
        reply = SiteMapClient(other, "site-2").add(panorama("kitchen", 1.2, 3.2), "kitchen")
        assert host.refresher.wait_idle(10.0) and wait_for(
            lambda: reply["place_id"] in host.runner.localizer.map.table.place_ids, 5.0
        )
