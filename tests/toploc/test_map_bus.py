"""Maps recorded over the bus (issue 12): ``map/add`` and ``map/connect`` on a running service
with the simulated robot, on real Zenoh sessions on 127.0.0.1; the localizer uses what was
added without a restart."""

from __future__ import annotations

import math
import re
import shutil
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from bus_helpers import free_endpoint, wait_for

from localizer.robot_protocol import Pose2D
from mapdb.database import MapDatabase
from mapdb.errors import ReadOnlyDatabaseError
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.worlds import make_world
from toploc import bus
from toploc.bus import BusConfig, open_session
from toploc.bus.png_codec import encode_png
from toploc.limits import Limits
from toploc.nodes import mapdb as mapdb_node
from toploc.nodes.localizer import LocalizerClient
from toploc.nodes.mapdb import MapClient
from toploc.service import Service, start_service

ROBOT_ID = "rmap"
CAMERA = PanoramaCamera(512, 96)
MAX_IMAGE_BYTES = 200_000


def robot_in(room: str, x_m: float, y_m: float, heading_deg: float = 30.0) -> SimulatedRobot:
    world = make_world("building")
    pose = world.building_pose(room, Pose2D(x_m, y_m, math.radians(heading_deg)))
    return SimulatedRobot(world, pose, camera=CAMERA, seed=9)


def panorama(room: str, x_m: float, y_m: float) -> bytes:
    return encode_png(robot_in(room, x_m, y_m).capture().image)


def n_places(db_path: Path) -> int:
    with MapDatabase.open(db_path, readonly=True) as map_db:
        return len(map_db.places())


@pytest.fixture(scope="module")
def service(building_map, tmp_path_factory) -> Iterator[tuple[Service, str, Path]]:
    """A service on a copy of the building map, the robot in the kitchen; quick refreshes and
    no re-calibration."""
    db_path = tmp_path_factory.mktemp("mapbus") / "map.db"
    shutil.copy(building_map[0], db_path)
    endpoint = free_endpoint()
    config = BusConfig(robot_id=ROBOT_ID, listen=(endpoint,))
    limits = Limits(max_image_bytes=MAX_IMAGE_BYTES)
    robot = robot_in("kitchen", 2.2, 2.9, 75.0)
    with start_service(
        db_path, config, robot, limits=limits, refresh_settle_s=0.1, recalibrate=False
    ) as running:
        yield running, endpoint, db_path


@pytest.fixture
def client(service) -> Iterator[MapClient]:
    _, endpoint, _ = service
    with open_session(BusConfig(robot_id=ROBOT_ID, listen=(), connect=(endpoint,))) as session:
        yield MapClient(session, ROBOT_ID)


def test_a_place_added_over_the_bus_is_in_the_map_and_in_the_next_localization(service, client):
    running, _, db_path = service
    before = n_places(db_path)
    here = robot_in("kitchen", 2.2, 2.9, 75.0).capture().image  # where the robot stands
    reply = client.add(encode_png(here), "kitchen", x_m=2.2, y_m=2.9, heading_deg=75.0)
    assert reply["new"] and reply["room"] == "kitchen" and reply["fingerprints"]["sift"] > 50
    assert reply["refresh_after_s"] == 0.1
    place_id = reply["place_id"]
    added = [p for p in client.places("kitchen") if p["id"] == place_id]
    assert added and added[0]["x_m"] == 2.2 and added[0]["heading_deg"] == 75.0
    assert n_places(db_path) == before + 1
    # the map/changed sample may reach the refresher after the reply: wait for the place itself
    assert wait_for(lambda: place_id in {p.id for p in running.runner.localizer.map.places}, 10)
    localizer = LocalizerClient(client.session, ROBOT_ID, timeout_s=10, localize_timeout_s=60)
    belief = localizer.localize(active=False)
    assert belief["best_place"]["place_id"] == place_id
    again = client.add(encode_png(here), "kitchen", x_m=2.2, y_m=2.9, heading_deg=75.0)
    assert again["place_id"] == place_id and not again["new"]


def test_the_same_image_under_another_room_is_a_conflict_that_adds_nothing(service, client):
    _, _, db_path = service
    image = encode_png(robot_in("kitchen", 1.4, 2.0, 10.0).capture().image)
    client.add(image, "kitchen", x_m=1.4, y_m=2.0, heading_deg=10.0)
    before = n_places(db_path)
    with pytest.raises(bus.BusReplyError, match=r"already place .* of room 'kitchen'"):
        client.add(image, "office_a", x_m=1.4, y_m=2.0, heading_deg=10.0)
    conflict = re.escape("sent for room 'kitchen' at (1.4, 2.0, None)")
    with pytest.raises(bus.BusReplyError, match=conflict):
        client.add(image, "kitchen", x_m=1.4, y_m=2.0)
    assert n_places(db_path) == before


def test_a_new_room_and_its_edge_reach_the_localizer(service, client):
    running, _, _ = service
    reply = client.add(panorama("storage", 1.0, 1.0), "annex")
    assert reply["new"]
    assert client.connect("annex", "corridor")["added"]
    assert not client.connect("corridor", "annex")["added"]
    localizer = LocalizerClient(client.session, ROBOT_ID)

    def refreshed() -> bool:  # the map with the edge, and the belief a client sees after it
        edges = running.runner.localizer.map.edges
        return ("annex", "corridor") in edges and "annex" in localizer.belief()["rooms"]

    assert wait_for(refreshed, 10)
    assert "annex" in running.runner.localizer.map.rooms


def test_connect_names_an_unknown_room(client):
    with pytest.raises(bus.BusReplyError, match="field 'room_b': unknown room 'nowhere'"):
        client.connect("kitchen", "nowhere")


def _raw_add(client: MapClient, payload: bytes, attachment: bytes) -> None:
    bus.request(client.session, client.key(bus.MAP_ADD), payload, 10.0, attachment=attachment)


GOOD_META = b'{"schema": 1, "kind": "add", "room": "kitchen"}'


@pytest.mark.parametrize(
    ("payload", "attachment", "message"),
    [
        (b"not a png at all", GOOD_META, "not a PNG image"),
        (b"\x89PNG\r\n\x1a\n" + b"\0" * 100, GOOD_META, "corrupt or truncated PNG"),
        (b"\x89PNG\r\n\x1a\n" + b"\0" * MAX_IMAGE_BYTES, GOOD_META, "max_image_bytes"),
        (None, b'{"schema": 1, "kind": "connect", "room": "kitchen"}', "kind 'connect'"),
        (None, b'{"schema": 1, "kind": "add", "room": "k", "x_m": NaN, "y_m": 0}', "'x_m'"),
        (None, b'{"schema": 1, "kind": "add", "room": "k", "x_m": 1.0}', "'x_m' and 'y_m'"),
        (None, b'{"schema": 1, "kind": "add", "room": "' + b"r" * 129 + b'"}', "'room'"),
        (None, b'{"schema": 1, "kind": "add", "room": "a\\nb"}', "control character"),
        (None, b'{"schema": 1, "kind": "add"}', "missing field 'room'"),
        (None, b'{"schema": 1, "kind": "add", "room": "k", "leg_from": 1}', "odometry position"),
        (
            None,
            b'{"schema": 1, "kind": "add", "room": "k", "x_m": 1, "y_m": 0, "leg_via": []}',
            "'leg_via' needs 'leg_from'",
        ),
        (
            None,
            b'{"schema":1,"kind":"add","room":"k","x_m":1,"y_m":0,"leg_from":1,"leg_via":[[1]]}',
            "field 'leg_via': leg via point 0 must be two finite numbers",
        ),
        (
            None,
            b'{"schema":1,"kind":"add","room":"k","x_m":1,"y_m":0,"leg_from":1,"leg_via":[7]}',
            "field 'leg_via'",
        ),
        (None, None, "empty payload"),
    ],
)
def test_a_bad_add_gets_an_error_naming_it_and_leaves_the_map_unchanged(
    service, client, payload, attachment, message
):
    _, _, db_path = service
    before = n_places(db_path)
    if payload is None:
        payload = panorama("kitchen", 1.0, 1.0)
    with pytest.raises(bus.BusReplyError, match=message):
        _raw_add(client, payload, attachment)
    assert n_places(db_path) == before


def test_an_add_of_a_pinhole_photo_is_refused_as_no_360_panorama(service, client):
    _, _, db_path = service
    before = n_places(db_path)
    crop = robot_in("kitchen", 1.0, 1.0).capture().image[:, 100:228]  # 128 x 96: 4:3
    with pytest.raises(bus.BusReplyError, match=r"128x96 px \(1.33:1\) is not a 360° panorama"):
        client.add(encode_png(crop), "kitchen")
    assert n_places(db_path) == before


def test_a_read_only_map_refuses_the_add_clearly(service, client, monkeypatch):
    _, _, db_path = service
    before = n_places(db_path)
    real_open = MapDatabase.open

    def open_read_only_media(path, **kwargs):
        if not kwargs.get("readonly"):
            raise ReadOnlyDatabaseError(f"{path} is read-only, cannot write to it", path)
        return real_open(path, **kwargs)

    monkeypatch.setattr(mapdb_node.MapDatabase, "open", open_read_only_media)
    with pytest.raises(bus.BusReplyError, match="the map cannot be written, nothing was added"):
        client.add(panorama("kitchen", 1.5, 1.5), "kitchen")
    with pytest.raises(bus.BusReplyError, match="is read-only"):
        client.connect("kitchen", "corridor")
    assert n_places(db_path) == before


def test_the_built_in_map_is_never_written_over_the_bus(building_map, tmp_path):
    db_path = tmp_path / "map.db"
    shutil.copy(building_map[0], db_path)
    before = n_places(db_path)
    endpoint = free_endpoint()
    config = BusConfig(robot_id="rbuiltin", listen=(endpoint,))
    robot = robot_in("kitchen", 2.2, 2.9, 75.0)
    client_config = BusConfig(robot_id="rbuiltin", listen=(), connect=(endpoint,))
    with (
        start_service(db_path, config, robot, builtin_map=True, recalibrate=False),
        open_session(client_config) as session,
    ):
        client = MapClient(session, "rbuiltin")
        advice = "toploc serve --db FILE --new-map"
        with pytest.raises(bus.BusReplyError, match=f"built-in map.*{advice}"):
            client.add(panorama("kitchen", 1.5, 1.5), "kitchen")
        with pytest.raises(bus.BusReplyError, match=f"built-in map.*{advice}"):
            client.connect("kitchen", "seminar")
        assert len(client.places("kitchen")) > 0  # reading it is as before
    assert n_places(db_path) == before


@dataclass(frozen=True)
class FakeMap:
    """What the refresher reads of a loaded map (it logs the counts)."""

    label: str
    places: tuple[object, ...] = ()
    rooms: tuple[str, ...] = ()


class FakeRunner:
    def __init__(self) -> None:
        self.maps: list[object] = []

    def replace_map(self, loaded: object) -> bool:
        self.maps.append(loaded)
        return True


def test_the_refresher_waits_for_changes_to_settle_then_reloads_and_recalibrates(
    building_map, monkeypatch
):
    from toploc import service as service_module

    calls: list[str] = []
    monkeypatch.setattr(
        service_module, "load_map", lambda path, detector: FakeMap(f"map {len(calls)}")
    )
    monkeypatch.setattr(service_module, "calibrate_map", lambda path, d: calls.append(d))
    runner = FakeRunner()
    refresher = service_module.MapRefresher(
        building_map[0],
        runner,
        "sift",
        settle_s=2.0,
        recalibrate=True,  # type: ignore[arg-type]
    )
    try:
        for _ in range(5):  # a burst of adds: one refresh after the last
            refresher.changed()
            time.sleep(0.05)
        assert runner.maps == []
        assert refresher.wait_idle(5)
        assert calls == ["sift"]  # the map's one detector, once
        labels = [m.label for m in runner.maps]  # type: ignore[attr-defined]
        assert labels == ["map 0", "map 1"]  # the new places, then the new likelihood
        refresher.changed()
        assert refresher.wait_idle(5) and calls == ["sift", "sift"]
    finally:
        refresher.close()


def test_a_stream_of_changes_is_refreshed_within_the_max_delay(building_map, monkeypatch):
    from toploc import service as service_module

    monkeypatch.setattr(service_module, "load_map", lambda path, detector: FakeMap("grown"))
    runner = FakeRunner()
    refresher = service_module.MapRefresher(
        building_map[0], runner, "sift", settle_s=0.5, recalibrate=False,  # type: ignore[arg-type]
        max_delay_s=1.0,
    )  # fmt: skip
    try:
        start_s = time.monotonic()
        while not runner.maps and time.monotonic() - start_s < 3.0:
            refresher.changed()  # never 0.5 s without a change
            time.sleep(0.1)
        assert runner.maps and time.monotonic() - start_s < 1.5
    finally:
        refresher.close()


def test_a_site_map_node_re_calibrates_after_the_writes_settle(building_map, monkeypatch):
    from toploc import service as service_module

    calls: list[str] = []
    monkeypatch.setattr(service_module, "calibrate_map", lambda path, d: calls.append(d))
    refresher = service_module.MapRefresher(building_map[0], None, "sift", settle_s=0.1)
    try:
        refresher.changed()
        assert refresher.wait_idle(5) and calls == ["sift"] and refresher.reloads == 0
    finally:
        refresher.close()


def test_the_docs_recording_example_runs(service, tmp_path, monkeypatch, capsys):
    _, endpoint, _ = service
    page = Path(__file__).resolve().parents[2] / "docs" / "robot.md"
    section = page.read_text(encoding="utf-8").split("## Recording a map on the robot", 1)[1]
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    code = code.replace('"tcp/127.0.0.1:7447"', repr(endpoint))
    code = code.replace("config.robot_id", repr(ROBOT_ID))
    (tmp_path / "kitchen.png").write_bytes(panorama("kitchen", 1.5, 2.5))
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "docs/robot.md", "exec"), {})
    assert int(capsys.readouterr().out.strip()) > 0
