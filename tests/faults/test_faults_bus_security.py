"""Who may command the robot, and one robot per id, on real Zenoh sessions on 127.0.0.1.

The service and operator configurations are the docs' own (docs/security.md), with a
dictionary of this test's; users: ``operator`` (may command), ``viewer`` (logged in, may watch),
``robot-node`` (a robot base on another machine).
"""

import json
import re
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import zenoh
from bus_helpers import free_endpoint, wait_for
from click.testing import CliRunner

from localizer.belief import LocalizationState, RoomBelief
from localizer.robot_protocol import Capture, MoveResult, Pose2D
from mapdb.database import MapDatabase
from mapdb.records import Fingerprint, NewPlace
from toploc import bus
from toploc.bus.config import bus_config, client_bus_config
from toploc.cli import main
from toploc.nodes.localizer import LocalizerClient, LocalizerNode
from toploc.nodes.robot import RemoteRobot, RobotNode
from toploc.service import start_service

SECURITY_PAGE = Path(__file__).resolve().parents[2] / "docs" / "security.md"
PASSWORDS = {"operator": "change-me", "viewer": "viewer-secret", "robot-node": "node-secret"}
ROBOT_ID = "r1"


def docs_json5_blocks() -> list[str]:
    """The ```json5 blocks of the docs' Security page, in order."""
    text = SECURITY_PAGE.read_text(encoding="utf-8")
    return re.findall(r"```json5\n(.*?)```", text, flags=re.DOTALL)


class FakeRobot:
    """A robot that records its moves."""

    def __init__(self) -> None:
        self.moves: list[tuple[float, float]] = []

    def capture(self) -> Capture:
        return Capture(np.zeros((8, 32, 3), dtype=np.uint8), stamp_s=1.0, source="fake")

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        self.moves.append((turn_rad, forward_m))
        return MoveResult(turn_rad, forward_m, bumped=False)

    def odometry(self) -> Pose2D:
        return Pose2D(0.0, 0.0, 0.0)

    def stop(self) -> None:
        """Moves are instantaneous here: nothing to stop."""


class Files:
    """The docs' service file, a user's file per user, and the same service without ACL."""

    def __init__(self, root: Path) -> None:
        service, operator = docs_json5_blocks()[:2]
        dictionary = root / "credentials.txt"
        dictionary.write_text("".join(f"{u}:{p}\n" for u, p in PASSWORDS.items()))
        self.service = root / "service.json5"
        self.service.write_text(service.replace("/etc/toploc/credentials.txt", str(dictionary)))
        self.service_without_acl = root / "service-without-acl.json5"
        auth = json.dumps({"transport": {"auth": {"usrpwd": {"dictionary_file": str(dictionary)}}}})
        self.service_without_acl.write_text(auth)
        self.root, self.operator_text = root, operator

    def user(self, user: str, password: str | None = None) -> Path:
        """The docs' operator file with ``user`` and ``password`` (its own by default)."""
        path = self.root / f"{user}.json5"
        text = self.operator_text.replace('user: "operator"', f'user: "{user}"')
        text = text.replace('"change-me"', f'"{password or PASSWORDS.get(user, "none")}"')
        path.write_text(text)
        return path


@pytest.fixture
def files(tmp_path: Path) -> Files:
    return Files(tmp_path)


class Service:
    """A robot node on a service session that listens on a free port with ``config_file``."""

    def __init__(self, config_file: Path | None) -> None:
        self.endpoint = free_endpoint()
        config = bus_config(ROBOT_ID, config_file, listen=[self.endpoint])
        self.session = bus.open_session(config)
        self.robot = FakeRobot()
        self.node = RobotNode(self.session, ROBOT_ID, self.robot)

    def peer(self, config_file: Path | None) -> zenoh.Session:
        """A client session with ``config_file`` connected (if it may) to the service."""
        return bus.open_session(client_bus_config(ROBOT_ID, config_file, [self.endpoint]))

    def close(self) -> None:
        self.node.close()
        self.session.close()


@pytest.fixture
def service(files: Files) -> Iterator[Service]:
    running = Service(files.service)
    yield running
    running.close()


def test_the_docs_have_a_service_and_an_operator_file():
    service, operator = docs_json5_blocks()[:2]
    assert "access_control" in service and "dictionary_file" in service
    assert 'user: "operator"' in operator


def test_only_the_operator_may_drive_the_robot(files, service):
    with service.peer(files.user("operator")) as session:
        moved = RemoteRobot(session, ROBOT_ID, timeout_s=2.0, move_timeout_s=2.0).move(0.0, 0.5)
        assert moved.moved_m == 0.5 and service.robot.moves == [(0.0, 0.5)]
    with service.peer(files.user("viewer")) as session:
        viewer = RemoteRobot(session, ROBOT_ID, timeout_s=2.0, move_timeout_s=2.0)
        assert viewer.odometry().x_m == 0.0  # logged in: it may watch
        start = time.monotonic()
        with pytest.raises(bus.BusTimeout, match="base/cmd: no reply"):
            viewer.move(0.0, 1.0)
        assert time.monotonic() - start < 1.9  # denied at once, before the 2 s timeout
        with pytest.raises(bus.BusTimeout, match="camera/capture: no reply"):
            viewer.capture()
    assert service.robot.moves == [(0.0, 0.5)]


def test_only_the_operator_may_query_map_add(files, service):
    """``map/add`` is a queryable: a viewer's query must not reach it (the map node's own
    handler is tested in tests/toploc/test_map_bus.py; here one that records who got through)."""
    reached: list[bytes] = []

    def add(payload: bytes | None) -> bus.Reply:
        reached.append(payload or b"")
        return bus.Reply(bus.encode("added", {"place_id": len(reached)}))

    queryable = bus.serve(service.session, bus.key(ROBOT_ID, bus.MAP_ADD), add)
    try:
        for user in ("viewer", "operator"):
            with service.peer(files.user(user)) as session:
                try:
                    bus.request(session, bus.key(ROBOT_ID, bus.MAP_ADD), user.encode(), 2.0)
                except bus.BusTimeout:
                    assert user == "viewer"
    finally:
        queryable.undeclare()
    assert reached == [b"operator"]


@pytest.mark.parametrize(
    ("user", "password"), [("operator", "wrong"), ("nobody", "x"), (None, None)]
)
def test_a_peer_without_valid_credentials_gets_no_session(files, service, user, password):
    config_file = None if user is None else files.user(user, password)
    with service.peer(config_file) as session:
        assert not bus.connected(session)
        with pytest.raises(bus.BusTimeout, match="accept this session's credentials"):
            LocalizerClient(session, ROBOT_ID, timeout_s=0.2).belief()


def test_without_the_acl_the_viewer_drives_the_robot(files):
    unguarded = Service(files.service_without_acl)
    try:
        with unguarded.peer(files.user("viewer")) as session:
            RemoteRobot(session, ROBOT_ID, move_timeout_s=2.0).move(0.0, 1.0)
        assert unguarded.robot.moves == [(0.0, 1.0)]
    finally:
        unguarded.close()


def test_a_robot_base_elsewhere_serves_the_service_as_robot_node(files):
    endpoint = free_endpoint()
    with bus.open_session(bus_config(ROBOT_ID, files.service, listen=[endpoint])) as session:
        base_config = client_bus_config(ROBOT_ID, files.user("robot-node"), [endpoint])
        base_robot = FakeRobot()
        with bus.open_session(base_config) as base, RobotNode(base, ROBOT_ID, base_robot):
            remote = RemoteRobot(session, ROBOT_ID, timeout_s=2.0, move_timeout_s=2.0)
            assert wait_for(lambda: _moves(remote))
        assert base_robot.moves


def _moves(remote: RemoteRobot) -> bool:
    try:
        remote.move(0.1, 0.0)
    except bus.BusTimeout:
        return False
    return True


# --- one robot per id ------------------------------------------------------------------------


@pytest.fixture
def tiny_map(tmp_path: Path) -> Path:
    db_path = tmp_path / "map.db"
    with MapDatabase.open(db_path) as map_db:
        place = NewPlace("office_a", "ab" * 32, "a.png", x_m=1.0, y_m=2.0, heading_deg=90.0)
        map_db.add_place(place, [Fingerprint.empty("sift", 96, 24)])
    return db_path


def test_a_second_service_with_the_same_robot_id_refuses_to_start(tiny_map):
    first = free_endpoint()
    with start_service(tiny_map, bus.BusConfig(ROBOT_ID, listen=(first,)), FakeRobot()):
        second = bus.BusConfig(ROBOT_ID, listen=(free_endpoint(),), connect=(first,))
        start = time.monotonic()
        with (
            pytest.raises(bus.BusIdInUse) as refused,
            start_service(tiny_map, second, FakeRobot()),
        ):
            pass
        assert time.monotonic() - start < 10.0  # a hang guard: the check itself waits <= 1 s
        assert str(refused.value) == (  # the first node it starts is the robot's
            f"robot id '{ROBOT_ID}' already has a robot node on the bus "
            f"(toploc/{ROBOT_ID}/alive/robot); choose another --robot-id"
        )
        other = bus.BusConfig("r2", listen=(free_endpoint(),), connect=(first,))
        with start_service(tiny_map, other, FakeRobot()) as started:
            assert bus.connected(started.session)


def test_a_node_refuses_a_role_already_taken_on_its_own_session():
    with bus.open_session(bus.BusConfig(ROBOT_ID, listen=(free_endpoint(),))) as session:
        with (
            RobotNode(session, ROBOT_ID, FakeRobot()),
            pytest.raises(bus.BusIdInUse, match="already has a robot node"),
        ):
            RobotNode(session, ROBOT_ID, FakeRobot())
        RobotNode(session, ROBOT_ID, FakeRobot()).close()  # free again once closed


def test_serve_refuses_a_taken_robot_id_in_one_line(tiny_map):
    first = free_endpoint()
    with start_service(tiny_map, bus.BusConfig("taken", listen=(first,))):
        args = ["serve", "--db", str(tiny_map), "--robot-id", "taken", "--no-sim"]
        done = CliRunner().invoke(main, [*args, "--listen", free_endpoint(), "--connect", first])
    assert done.exit_code == 1, done.output
    # without a robot, the first node it starts is the localizer
    assert "Error: robot id 'taken' already has a localizer node on the bus" in done.output
    assert "Traceback" not in done.output


# --- the CLI: warnings and bad files ---------------------------------------------------------


class _Stopped(bus.BusError):
    pass


@pytest.fixture
def serve_stops_at_once(monkeypatch):
    """``serve`` runs up to starting the service, which then fails with "stopped here"."""

    def fail(*_args, **_kwargs):
        raise _Stopped("stopped here")

    monkeypatch.setattr("toploc.commands.serve.start_service", fail)


@pytest.mark.parametrize(
    ("listen", "warns"),
    [
        ("tcp/0.0.0.0:7447", True),
        ("tcp/[::]:7447", True),
        ("tcp/192.168.1.5:7447", True),
        ("tcp/127.0.0.1:7447", False),
        ("tcp/[::1]:7447", False),
        ("tcp/localhost:7447", False),
    ],
)
def test_serve_warns_when_it_listens_beyond_loopback_unauthenticated(
    tiny_map, serve_stops_at_once, listen, warns
):
    args = ["serve", "--db", str(tiny_map), "--no-sim", "--robot-id", "r9", "--listen", listen]
    done = CliRunner().invoke(main, args)
    assert "stopped here" in done.output
    assert "robot id: r9" in done.stdout
    assert ("WARNING: listening on" in done.stderr) is warns
    assert "WARNING" not in done.stdout


def test_serve_does_not_warn_when_peers_must_log_in(tiny_map, files, serve_stops_at_once):
    args = ["serve", "--db", str(tiny_map), "--no-sim", "--listen", "tcp/0.0.0.0:7447"]
    done = CliRunner().invoke(main, [*args, "--zenoh-config", str(files.service)])
    assert "stopped here" in done.output
    assert "WARNING" not in done.stderr


def test_serve_and_belief_name_a_bad_zenoh_file_in_one_line(tmp_path, tiny_map, monkeypatch):
    bad = tmp_path / "bad.json5"
    bad.write_text('{mode: "bogus"}')
    for args in (["serve", "--db", str(tiny_map), "--no-sim"], ["belief"]):
        done = CliRunner().invoke(main, [*args, "--zenoh-config", str(bad)])
        assert done.exit_code == 1
        assert done.output.startswith(f"Error: Zenoh configuration {bad}: ")
        assert "unknown variant `bogus`" in done.output and len(done.output.splitlines()) == 1
    monkeypatch.setenv("TOPLOC_ZENOH_CONFIG", str(bad))
    done = CliRunner().invoke(main, ["belief"])
    assert f"Error: Zenoh configuration {bad}: " in done.output


def test_belief_logs_in_with_the_env_file_and_uses_the_default_robot_id(files, monkeypatch):
    endpoint = free_endpoint()
    robot_id = bus.default_robot_id()
    config = bus_config(robot_id, files.service, listen=[endpoint])
    with bus.open_session(config) as session, _FakeLocalizer(session, robot_id):
        monkeypatch.setenv("TOPLOC_ZENOH_CONFIG", str(files.user("viewer")))
        done = CliRunner().invoke(main, ["belief", "--connect", endpoint, "--json"])
        assert done.exit_code == 0, done.output
        assert '"state": "localized"' in done.output
        done = CliRunner().invoke(main, ["belief", "--connect", endpoint, "--reset"])
        assert done.exit_code == 1
        assert f"toploc/{robot_id}/localizer/reset: no reply" in done.output


class _FakeLocalizer:
    """A localizer node whose belief is office_a, localized."""

    def __init__(self, session: zenoh.Session, robot_id: str) -> None:
        self.current = RoomBelief(
            rooms=("office_a", "office_b"),
            probabilities=(0.9, 0.1),
            state=LocalizationState.LOCALIZED,
            entropy_bits=0.469,
            best_place_id=4,
            best_place_inliers=37,
            stamp_s=1.0,
            best_place_room="office_a",
        ).to_json()
        self.node = LocalizerNode(session, robot_id, self)

    def belief(self) -> dict:
        return self.current

    def localize(self, active: bool) -> dict:
        return self.current

    def reset(self, prior: object) -> dict:
        return self.current

    def __enter__(self) -> "_FakeLocalizer":
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.node.close()
