"""The service's log: one INFO line per localization, map add, map reload and recalibration,
and the levels ``-v``/``--log-level`` choose (toploc/logs.py)."""

from __future__ import annotations

import io
import logging
import math
import re

import pytest
from bus_helpers import free_endpoint
from click.testing import CliRunner

from mapdb.database import MapDatabase
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.world import Pose2D
from robot.worlds import make_world
from toploc.bus import BusConfig, open_session
from toploc.cli import main
from toploc.logs import chosen_level, configure_logging
from toploc.nodes.camera import encode_png
from toploc.nodes.localizer import LocalizerClient
from toploc.nodes.mapdb import MapClient
from toploc.service import start_service

ROBOT_ID = "rlog"
CAMERA = PanoramaCamera(512, 96)
PLACES = (("kitchen", 1.4, 2.0), ("kitchen", 2.2, 2.9), ("seminar", 3.1, 3.3))


def robot_in(room: str, x_m: float, y_m: float) -> SimulatedRobot:
    world = make_world("building")
    pose = world.building_pose(room, Pose2D(x_m, y_m, math.radians(40.0)))
    return SimulatedRobot(world, pose, camera=CAMERA, seed=3)


def messages(caplog: pytest.LogCaptureFixture, logger: str) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == logger and r.levelname == "INFO"]


def test_map_adds_the_reloads_they_bring_and_a_localization_are_logged(tmp_path, caplog):
    caplog.set_level(logging.INFO, logger="toploc")
    db_path = tmp_path / "map.db"
    MapDatabase.open(db_path, create=True).close()
    endpoint = free_endpoint()
    config = BusConfig(robot_id=ROBOT_ID, listen=(endpoint,))
    client_config = BusConfig(robot_id=ROBOT_ID, listen=(), connect=(endpoint,))
    with (
        start_service(
            db_path, config, robot_in("kitchen", 2.0, 3.0), refresh_settle_s=0.1, allow_empty=True
        ) as service,
        open_session(client_config) as session,
    ):
        added = [
            MapClient(session, ROBOT_ID).add(encode_png(robot_in(room, x_m, y_m).capture().image),
                                             room, x_m=x_m, y_m=y_m)
            for room, x_m, y_m in PLACES
        ]  # fmt: skip
        assert messages(caplog, "toploc.nodes.mapdb") == [
            f"map add: place {a['place_id']} in room {room} (new; features sift "
            f"{a['fingerprints']['sift']})"
            for a, (room, _, _) in zip(added, PLACES, strict=True)
        ]
        assert service.refresher.wait_idle(60)
        localizer = LocalizerClient(session, ROBOT_ID, timeout_s=30.0)
        belief = localizer.localize(active=False)
        localizer.reset({"seminar": 1.0})
    reloads = [m for m in messages(caplog, "toploc.service") if " reloaded " in m]
    assert reloads[-1] == (
        f"map {db_path} reloaded (version {len(reloads)} since start): {len(PLACES)} places, "
        "2 rooms"
    )
    calibrations = [m for m in messages(caplog, "toploc.service") if m not in reloads]
    assert calibrations and all(
        re.fullmatch(rf"map {re.escape(str(db_path))}: sift likelihood re-calibrated in "
                     r"\d+\.\d s", m)
        for m in calibrations
    ), calibrations  # fmt: skip
    localized, reset = messages(caplog, "toploc.runner")
    assert reset == "belief reset to the prior {'seminar': 1.0}"
    top = belief["top"]
    assert re.fullmatch(
        rf"localization \(passive\): {belief['state']}, top {top['room']} "
        rf"{top['probability']:.3f}, {belief['best_place']['inliers']} inliers, \d+ ms",
        localized,
    ), localized


@pytest.mark.parametrize(
    ("command", "verbose", "log_level", "expected"),
    [
        ("map", 0, None, logging.WARNING),
        ("map", 1, None, logging.INFO),
        ("map", 2, None, logging.DEBUG),
        ("serve", 0, None, logging.INFO),
        ("node", 0, None, logging.INFO),
        ("serve", 1, None, logging.DEBUG),
        ("serve", 5, None, logging.DEBUG),
        ("serve", 0, "error", logging.ERROR),
        ("map", 2, "WARNING", logging.WARNING),
    ],
)
def test_the_level_is_the_commands_default_lowered_per_v_unless_named(
    command, verbose, log_level, expected
):
    assert chosen_level(command, verbose, log_level) == expected


def test_a_log_line_has_a_timestamp_the_level_and_the_logger_name():
    stream = io.StringIO()
    configure_logging(logging.INFO, stream)
    try:
        logging.getLogger("toploc.runner").info("localization (passive): %s", "localized")
        logging.getLogger("toploc.runner").debug("not shown at INFO")
        logging.getLogger("some.library").info("not shown: other libraries log warnings")
    finally:
        configure_logging(logging.WARNING)
    assert re.fullmatch(
        r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3} INFO toploc\.runner: localization \(passive\): "
        r"localized\n",
        stream.getvalue(),
    ), stream.getvalue()


def test_an_unknown_log_level_is_refused():
    done = CliRunner().invoke(main, ["--log-level", "chatty", "belief"])
    assert done.exit_code == 2
    assert "'chatty' is not one of" in done.output


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        ([], logging.WARNING),
        (["-v"], logging.INFO),
        (["-vv"], logging.DEBUG),
        (["--log-level", "error", "-v"], logging.ERROR),
    ],
)
def test_the_group_sets_the_level_of_the_command_it_runs(args, expected):
    try:
        done = CliRunner().invoke(main, [*args, "drive", "--connect", free_endpoint(), "--stop",
                                         "--timeout", "0.2"])  # fmt: skip
        assert done.exit_code == 1  # nothing answers; the level is set before the command runs
        assert logging.getLogger("toploc").level == expected
    finally:
        configure_logging(logging.WARNING)
