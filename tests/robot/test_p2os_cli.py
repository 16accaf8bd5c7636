"""``toploc sim p2os`` (a subprocess on a pty) and ``toploc serve --robot`` (issue 12)."""

from __future__ import annotations

import math
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from localizer.active import ActiveParams, localize_actively
from localizer.belief import LocalizationState
from localizer.loaded_map import LoadedMap
from localizer.localizer import Localizer
from localizer.visual_homing import HomingParams, HomingResult, drive_home
from mapdb.database import MapDatabase
from mapdb.loading import load_snapshot
from mapdb.records import Fingerprint, NewPlace
from robot.p2os_base import P2osBase, P2osSettings
from toploc.cli import main
from toploc.robots import RobotSpec, open_robot, parse_robot_spec

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def tiny_map(tmp_path: Path) -> Path:
    db_path = tmp_path / "map.db"
    with MapDatabase.open(db_path) as map_db:
        place = NewPlace("office_b", "ab" * 32, "a.png", x_m=1.0, y_m=2.0, heading_deg=90.0)
        map_db.add_place(place, [Fingerprint.empty("sift", 96, 24)])
    return db_path


def test_robot_specs() -> None:
    assert parse_robot_spec("sim") == RobotSpec("sim")
    assert parse_robot_spec("p2os-sim") == RobotSpec("p2os-sim")
    assert parse_robot_spec("p2os:/dev/ttyUSB0") == RobotSpec("p2os", "/dev/ttyUSB0")
    assert parse_robot_spec("p2os:/dev/ttyUSB0@P3DX") == RobotSpec("p2os", "/dev/ttyUSB0", "P3DX")
    for bad in ("p2os:", "pioneer", "", "p2os:@p3dx", "p2os:/dev/ttyS0@"):
        with pytest.raises(ValueError, match=re.escape("a robot is sim | p2os-sim | p2os:PORT")):
            parse_robot_spec(bad)


def test_an_unknown_pioneer_model_names_the_known_ones() -> None:
    with pytest.raises(ValueError, match=r"unknown Pioneer model 'p9dx'; known: amigo, .*p3dx"):
        parse_robot_spec("p2os:/dev/ttyUSB0@p9dx")


def test_serve_with_a_missing_port_is_one_line(tiny_map: Path, tmp_path: Path) -> None:
    port = tmp_path / "ttyUSB0"
    args = ["serve", "--db", str(tiny_map), "--robot", f"p2os:{port}", "--robot-id", "p2"]
    done = CliRunner().invoke(main, args)
    assert done.exit_code == 1, done.output
    assert f"Error: cannot open serial port {port}" in done.output
    assert "Traceback" not in done.output
    done = CliRunner().invoke(main, ["serve", "--db", str(tiny_map), "--robot", "pioneer"])
    assert done.exit_code == 2 and "a robot is sim | p2os-sim | p2os:PORT" in done.output


def test_p2os_sim_robot_closes_the_loop_over_the_protocol(tiny_map: Path) -> None:
    with open_robot("p2os-sim", "building", "office_b", 1, tiny_map) as (robot, where):
        assert robot is not None and "over P2OS on /dev/pts/" in where
        before = robot.capture()
        result = robot.move(math.radians(30), 0.2)
        assert abs(result.turned_rad - math.radians(30)) < math.radians(3)
        after = robot.capture()
        assert before.image.shape == after.image.shape == (24, 96, 3)
        assert (before.image != after.image).any()  # rendered at the new true pose
        assert robot.odometry().heading_rad == pytest.approx(math.radians(30), abs=0.05)


def test_sim_p2os_command_prints_a_port_that_speaks_p2os(tmp_path: Path) -> None:
    link = tmp_path / "pioneer"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    command = [sys.executable, "-m", "toploc", "sim", "p2os", "--link", str(link),
               "--fault", "garbage", "--fault-every", "3"]  # fmt: skip
    process = subprocess.Popen(command, env=env, cwd=REPO, stdout=subprocess.PIPE, text=True)
    try:
        assert process.stdout is not None
        first = process.stdout.readline()
        assert first == f"port: {link}\n"
        with P2osBase(str(link), settings=P2osSettings(sync_timeout_s=5.0)) as base:
            assert base.robot_strings[1] == "Pioneer"
            result = base.move(0.0, 0.1)
            assert result.moved_m == pytest.approx(0.1, abs=0.03)
            assert base.parser.skipped_bytes > 0
        process.send_signal(signal.SIGINT)
        out, _ = process.communicate(timeout=10)
        assert process.returncode == 130 and out.strip().endswith("stopped")  # 130: Ctrl-C
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def test_an_active_localization_whose_drive_turns_half_round_ends_with_a_belief(
    building_map: tuple[Path, Path],
) -> None:
    """Issue 23: a homing step straight behind the robot (a turn of exactly 180 deg) over the
    real protocol ends, and the active localization with it, in a belief, not a P2osError."""
    db_path = building_map[0]
    localizer = Localizer(LoadedMap.from_snapshot(load_snapshot(db_path)))
    with open_robot("p2os-sim", "building", "office_b", 4, db_path) as (robot, _where):
        assert robot is not None
        turns: list[float] = []

        def home(place_id: int) -> HomingResult:
            turns.append(robot.move(math.pi, 0.0).turned_rad)  # the goal lies behind
            goal = localizer.map.fingerprint(place_id)
            return drive_home(robot, goal, localizer.extract, HomingParams(max_steps=2))

        params = ActiveParams(max_targets=1)
        result = localize_actively(localizer, robot, "most-likely", params, home=home)
    assert result.first.state is LocalizationState.AMBIGUOUS  # so it drove
    assert len(result.visits) == len(turns) == 1
    assert result.final.state in tuple(LocalizationState)
    assert all(abs(abs(turned) - math.pi) < math.radians(2.5) for turned in turns)
