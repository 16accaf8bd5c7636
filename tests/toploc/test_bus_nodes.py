"""The nodes on a real Zenoh bus: two peer sessions on 127.0.0.1, a free port per test."""

import json
import math
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest
from bus_helpers import ROBOT_ID, Bus, alive_nodes, free_port, make_belief, wait_for
from click.testing import CliRunner

from localizer.robot_protocol import Capture, MoveResult, Pose2D
from mapdb.database import MapDatabase
from mapdb.records import Fingerprint, NewPlace
from toploc import bus
from toploc.bus.png_codec import decode_png
from toploc.cli import main
from toploc.nodes.localizer import LocalizerClient, LocalizerNode
from toploc.nodes.mapdb import MapNode
from toploc.nodes.robot import RemoteRobot, RobotNode

# --- robot -----------------------------------------------------------------------------------


class FakeRobot:
    """A robot on a line: turns and drives exactly, but a wall stops it after 1 m in one move."""

    def __init__(self, grey: bool = False) -> None:
        rng = np.random.default_rng(7)
        shape = (24, 96) if grey else (24, 96, 3)
        self.image = rng.integers(0, 256, size=shape, dtype=np.uint8)
        self.x_m, self.y_m, self.heading_rad = 0.0, 0.0, 0.3
        self.moves: list[tuple[float, float]] = []

    def capture(self) -> Capture:
        return Capture(self.image.copy(), stamp_s=12.5, source="fake-camera")

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        self.moves.append((turn_rad, forward_m))
        moved_m = min(forward_m, 1.0)
        self.heading_rad += turn_rad
        self.x_m += moved_m * math.cos(self.heading_rad)
        self.y_m += moved_m * math.sin(self.heading_rad)
        return MoveResult(turn_rad, moved_m, bumped=moved_m < forward_m)

    def odometry(self) -> Pose2D:
        return Pose2D(self.x_m, self.y_m, self.heading_rad)

    def stop(self) -> None:
        """Moves are instantaneous here: nothing to stop."""


@pytest.fixture
def robot_bus(zbus: Bus) -> Iterator[tuple[Bus, FakeRobot, RemoteRobot]]:
    fake = FakeRobot()
    with RobotNode(zbus.server, ROBOT_ID, fake):
        zbus.wait_alive("robot")
        remote = RemoteRobot(zbus.client, ROBOT_ID, timeout_s=2.0, move_timeout_s=2.0)
        yield zbus, fake, remote
        remote.close()


def test_capture_round_trip_is_lossless_and_published(robot_bus):
    zbus, fake, remote = robot_bus
    published: list[tuple[bytes, dict]] = []
    zbus.client.declare_subscriber(
        bus.key(ROBOT_ID, bus.CAMERA_PANORAMA),
        lambda s: published.append((s.payload.to_bytes(), json.loads(s.attachment.to_bytes()))),
    )
    captures = []
    # The subscriber's declaration reaches the node asynchronously: capture until it hears one.
    assert wait_for(lambda: captures.append(remote.capture()) is None and bool(published))
    capture = captures[-1]
    np.testing.assert_array_equal(capture.image, fake.image)
    assert (capture.stamp_s, capture.source) == (12.5, "fake-camera")
    meta = dict(remote.last_capture_meta)
    assert meta["heading_deg"] == pytest.approx(math.degrees(0.3))
    remote.capture()
    assert remote.last_capture_meta["capture_id"] == meta["capture_id"] + 1  # ids count captures
    png, attachment = published[0]
    assert attachment["capture_id"] <= meta["capture_id"] and attachment["source"] == "fake-camera"
    np.testing.assert_array_equal(decode_png("camera/panorama", png), fake.image)


def test_a_grey_panorama_stays_grey(zbus):
    fake = FakeRobot(grey=True)
    with RobotNode(zbus.server, ROBOT_ID, fake):
        zbus.wait_alive("robot")
        image = RemoteRobot(zbus.client, ROBOT_ID, timeout_s=2.0).capture().image
    assert image.shape == fake.image.shape
    np.testing.assert_array_equal(image, fake.image)


def test_move_round_trip_and_odometry(robot_bus):
    _, fake, remote = robot_bus
    assert remote.odometry() == pytest.approx(Pose2D(0.0, 0.0, 0.3))  # queried: no move yet
    result = remote.move(math.pi / 2, 0.5)
    assert fake.moves == [pytest.approx((math.pi / 2, 0.5))]
    assert result.turned_rad == pytest.approx(math.pi / 2)
    assert (result.moved_m, result.bumped) == (0.5, False)
    odometry = remote.odometry()  # right after the move: from the move reply, not stale
    assert (odometry.x_m, odometry.y_m) == pytest.approx((fake.x_m, fake.y_m))
    assert odometry.heading_rad == pytest.approx(fake.heading_rad)
    bumped = remote.move(0.0, 3.0)
    assert (bumped.moved_m, bumped.bumped) == (1.0, True)


@pytest.mark.parametrize(
    ("payload", "match"),
    [
        (None, "empty payload"),
        (b"turn 90", "not JSON"),
        (bus.encode("cmd", {"turn_deg": 90}), "missing field 'forward_m'"),
        (bus.encode("cmd", {"turn_deg": "90", "forward_m": 1}), "'turn_deg' must be float"),
        (b'{"schema": 2, "turn_deg": 0, "forward_m": 1}', "schema version 2"),
    ],
)
def test_a_malformed_command_leaves_the_robot_unmoved(robot_bus, payload, match):
    zbus, fake, _ = robot_bus
    with pytest.raises(bus.BusReplyError, match=match) as caught:
        bus.request(zbus.client, bus.key(ROBOT_ID, bus.BASE_CMD), payload, timeout_s=2.0)
    assert caught.value.key_expr == "toploc/r1/base/cmd"
    assert fake.moves == []


@pytest.mark.parametrize(
    ("payload", "attachment", "match"),
    [
        (b"\x89PNG\r\n\x1a\n truncated", bus.encode("capture", {}), "missing field 'capture_id'"),
        (
            b"\x89PNG\r\n\x1a\n truncated",
            bus.encode("capture", {"capture_id": 1, "stamp": 1, "heading_deg": 0, "source": "x"}),
            "not a decodable image",
        ),
        (b"", None, "no capture attachment"),
    ],
)
def test_a_corrupt_capture_reply_is_a_clear_error(zbus, payload, attachment, match):
    bus.serve(
        zbus.server,
        bus.key(ROBOT_ID, bus.CAMERA_CAPTURE),
        lambda _: bus.Reply(payload, attachment),
    )
    remote = RemoteRobot(zbus.client, ROBOT_ID, timeout_s=2.0)
    camera = bus.key(ROBOT_ID, "camera/*")
    assert wait_for(lambda: any(r.ok is not None for r in zbus.client.get(camera)))
    with pytest.raises(bus.BusMessageError, match=match):
        remote.capture()


# --- localizer -------------------------------------------------------------------------------


class FakeService:
    """Records calls; ``localize`` makes office_a likely, ``reset`` applies the prior."""

    def __init__(self) -> None:
        self.current = make_belief({"office_a": 0.5, "office_b": 0.5})
        self.calls: list[tuple] = []
        self.fail: Exception | None = None
        self.release: threading.Event | None = None

    def belief(self) -> dict:
        self.calls.append(("belief",))
        return self.current

    def localize(self, active: bool, deadline_s: float | None = None) -> dict:
        self.calls.append(("localize", active))
        if self.release is not None:
            assert self.release.wait(5.0)
        if self.fail is not None:
            raise self.fail
        self.current = make_belief({"office_a": 0.9, "office_b": 0.1}, "localized", 2.0)
        return self.current

    def reset(self, prior) -> dict:
        self.calls.append(("reset", prior))
        rooms = dict(prior) if prior else {"office_a": 0.5, "office_b": 0.5}
        total = sum(rooms.values())
        self.current = make_belief({r: p / total for r, p in rooms.items()}, "lost", 3.0)
        return self.current


@pytest.fixture
def localizer_bus(zbus: Bus) -> Iterator[tuple[Bus, FakeService, LocalizerNode, LocalizerClient]]:
    service = FakeService()
    with LocalizerNode(zbus.server, ROBOT_ID, service) as node:
        zbus.wait_alive("localizer")
        client = LocalizerClient(zbus.client, ROBOT_ID, timeout_s=2.0, localize_timeout_s=5.0)
        yield zbus, service, node, client
        client.close()


def test_belief_localize_reset_round_trip(localizer_bus):
    _, service, _, client = localizer_bus
    assert client.belief() == service.current
    localized = client.localize(active=True)
    assert localized["state"] == "localized" and localized["rooms"]["office_a"] == 0.9
    assert ("localize", True) in service.calls
    client.localize()
    assert service.calls[-1] == ("localize", False)
    reset = client.reset({"office_a": 1, "office_b": 3})
    assert service.calls[-1] == ("reset", {"office_a": 1.0, "office_b": 3.0})
    assert reset["rooms"] == {"office_a": 0.25, "office_b": 0.75}
    client.reset()
    assert service.calls[-1] == ("reset", None)


def test_subscribers_receive_each_changed_belief_once(localizer_bus):
    _, _, node, client = localizer_bus
    received: list[dict] = []
    client.subscribe(received.append)
    # The subscription reaches the node asynchronously: publish until one arrives.
    assert wait_for(lambda: node.publish(make_belief({"x": 1.0}, stamp=time.time())) and received)
    time.sleep(0.2)  # let warm-up publications still in flight arrive
    received.clear()
    belief = client.localize(active=False)
    assert wait_for(lambda: bool(received))
    assert received == [belief]
    assert not node.publish(belief)  # unchanged: not published again
    time.sleep(0.1)
    assert received == [belief]


def test_a_service_exception_becomes_an_error_reply_and_the_node_stays_up(localizer_bus):
    _, service, _, client = localizer_bus
    service.fail = RuntimeError("camera unplugged")
    with pytest.raises(bus.BusReplyError, match="RuntimeError: camera unplugged"):
        client.localize()
    assert client.belief()["state"] == "ambiguous"


def test_a_bad_belief_from_the_service_is_an_error_reply(localizer_bus):
    _, service, _, client = localizer_bus
    service.current = {**service.current, "state": "confused"}
    with pytest.raises(bus.BusReplyError, match="bad belief: state must be one of"):
        client.belief()


@pytest.mark.parametrize(
    ("suffix", "payload", "match"),
    [
        (
            bus.LOCALIZER_LOCALIZE,
            bus.encode("localize", {"active": "yes"}),
            "'active' must be bool",
        ),
        (bus.LOCALIZER_LOCALIZE, b"[true]", "must be a JSON object"),
        (bus.LOCALIZER_RESET, bus.encode("reset", {"prior": {"a": -1}}), r"prior\['a'\] must be"),
        (bus.LOCALIZER_RESET, bus.encode("reset", {"prior": [0.5]}), "prior must be a non-empty"),
    ],
)
def test_a_malformed_request_does_not_reach_the_service(localizer_bus, suffix, payload, match):
    zbus, service, _, _ = localizer_bus
    with pytest.raises(bus.BusReplyError, match=match):
        bus.request(zbus.client, bus.key(ROBOT_ID, suffix), payload, timeout_s=2.0)
    assert [c for c in service.calls if c[0] != "belief"] == []


def test_a_long_localize_does_not_block_belief_queries(localizer_bus):
    _, service, _, client = localizer_bus
    service.release = threading.Event()
    results: list[dict] = []
    worker = threading.Thread(target=lambda: results.append(client.localize(active=True)))
    worker.start()
    assert wait_for(lambda: ("localize", True) in service.calls)
    start = time.monotonic()
    assert client.belief()["state"] == "ambiguous"  # answered while localize is running
    assert client.reset()["state"] == "lost"
    elapsed_s = time.monotonic() - start
    service.release.set()
    worker.join(5.0)
    assert elapsed_s < 1.0
    assert results and results[0]["state"] == "localized"


# --- liveliness, timeouts, map, CLI ----------------------------------------------------------


def test_liveliness_tokens_come_and_go(zbus, tmp_path):
    with MapDatabase.open(tmp_path / "map.db"):
        pass
    robot_node = RobotNode(zbus.server, ROBOT_ID, FakeRobot())
    with (
        LocalizerNode(zbus.server, ROBOT_ID, FakeService()),
        MapNode(zbus.server, ROBOT_ID, tmp_path / "map.db"),
    ):
        everyone = {"robot", "camera", "localizer", "mapdb"}
        assert wait_for(lambda: alive_nodes(zbus.client) == everyone, timeout_s=10.0)
        robot_node.close()
        assert wait_for(lambda: alive_nodes(zbus.client) == {"localizer", "mapdb"}, 10.0)
    assert wait_for(lambda: alive_nodes(zbus.client) == set(), timeout_s=10.0)
    assert alive_nodes(zbus.client, "other") == set()


def test_nobody_answering_raises_bus_timeout_quickly(zbus):
    start = time.monotonic()
    with pytest.raises(bus.BusTimeout, match="toploc/ghost/localizer/belief: no reply"):
        LocalizerClient(zbus.client, "ghost", timeout_s=0.2).belief()
    with pytest.raises(bus.BusTimeout, match="camera/capture"):
        RemoteRobot(zbus.client, "ghost", timeout_s=0.2).capture()
    assert time.monotonic() - start < 1.0


def test_a_queryable_too_slow_raises_bus_timeout_after_the_timeout(zbus):
    slow_key = bus.key(ROBOT_ID, bus.BASE_CMD)
    bus.serve(zbus.server, slow_key, lambda _: time.sleep(0.6) or bus.Reply(b"{}"))
    assert wait_for(lambda: bool(list(zbus.client.get(slow_key, timeout=1.0))))
    start = time.monotonic()
    with pytest.raises(bus.BusTimeout):
        RemoteRobot(zbus.client, ROBOT_ID, move_timeout_s=0.2).move(0.0, 1.0)
    assert 0.15 < time.monotonic() - start < 0.5


def test_map_node_serves_rooms_places_and_edges(zbus, tmp_path):
    db_path = tmp_path / "map.db"
    with MapDatabase.open(db_path) as map_db:
        fingerprint = Fingerprint.empty("sift", 96, 24)
        place = NewPlace("office_a", "ab" * 32, "a.png", x_m=1.0, y_m=2.0, heading_deg=90.0)
        place_id = map_db.add_place(place, [fingerprint])
        map_db.add_room("corridor")
        map_db.connect_rooms("office_a", "corridor")
    with MapNode(zbus.server, ROBOT_ID, db_path):
        zbus.wait_alive("mapdb")
        get = lambda suffix, payload=None, fields=None: bus.request_json(  # noqa: E731
            zbus.client, bus.key(ROBOT_ID, suffix), fields or {}, payload, 2.0
        )
        rooms = get(bus.MAP_ROOMS, fields={"rooms": list})["rooms"]
        assert {(r["name"], r["n_places"]) for r in rooms} == {("office_a", 1), ("corridor", 0)}
        places = get(bus.MAP_PLACES, bus.encode("q", {"room": "office_a"}))["places"]
        assert [(p["id"], p["x_m"], p["heading_deg"]) for p in places] == [(place_id, 1.0, 90.0)]
        assert get(bus.MAP_PLACES, bus.encode("q", {"room": "corridor"}))["places"] == []
        assert get(bus.MAP_EDGES)["edges"] == [["corridor", "office_a"]]
        with pytest.raises(bus.BusReplyError, match="kitchen"):
            get(bus.MAP_PLACES, bus.encode("q", {"room": "kitchen"}))


def test_belief_cli_against_a_running_node(localizer_bus):
    zbus, service, _, _ = localizer_bus
    runner = CliRunner()
    args = ["belief", "--robot-id", ROBOT_ID, "--connect", zbus.endpoint, "--timeout", "2"]
    done = runner.invoke(main, [*args, "--json"])
    assert done.exit_code == 0, done.output
    assert json.loads(done.output) == service.current
    done = runner.invoke(main, [*args, "--reset", "--active"])
    assert done.exit_code == 0, done.output
    assert [c[0] for c in service.calls[-2:]] == ["reset", "localize"]
    assert service.calls[-1] == ("localize", True)
    assert "localized in office_a" in done.output
    assert "best place: place 4 in office_a (37 inliers)" in done.output
    assert done.output.index("office_a") < done.output.index("office_b")


def test_belief_cli_without_a_service_fails_clearly(zbus):
    done = CliRunner().invoke(
        main, ["belief", "--robot-id", "ghost", "--connect", zbus.endpoint, "--timeout", "0.2"]
    )
    assert done.exit_code == 1
    assert "Error: toploc/ghost/localizer/belief: no reply after" in done.output
    assert "is the node running" in done.output


def test_belief_cli_with_nothing_listening_says_so():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    done = CliRunner().invoke(main, ["belief", "--connect", endpoint, "--timeout", "0.2"])
    assert done.exit_code == 1
    assert f"toploc/{bus.default_robot_id()}/localizer/belief: no reply" in done.output
    assert "reaches no other Zenoh node" in done.output


def test_nodes_and_clients_meet_through_a_router_session():
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    client_cfg = bus.BusConfig(ROBOT_ID, "client", listen=(), connect=(endpoint,))
    with (
        bus.open_session(bus.BusConfig(ROBOT_ID, "router", listen=(endpoint,))),
        bus.open_session(client_cfg) as node_session,
        bus.open_session(client_cfg) as app_session,
    ):
        service = FakeService()
        with LocalizerNode(node_session, ROBOT_ID, service):
            assert wait_for(lambda: alive_nodes(app_session) == {"localizer"})
            assert LocalizerClient(app_session, ROBOT_ID, timeout_s=2.0).belief() == service.current


def test_a_busy_listen_port_is_a_clear_error(zbus):
    with pytest.raises(bus.BusError, match=f"listen \\['{zbus.endpoint}'\\].*in use"):
        bus.open_session(bus.BusConfig(ROBOT_ID, listen=(zbus.endpoint,)))
