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

from mapdb.database import MapDatabase
from mapdb.records import Fingerprint, NewPlace
from robot.p2os_base import P2osBase, P2osSettings
from toploc.cli import main
from toploc.robots import open_robot, parse_robot_spec

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def tiny_map(tmp_path: Path) -> Path:
    db_path = tmp_path / "map.db"
    with MapDatabase.open(db_path) as map_db:
        place = NewPlace("office_b", "ab" * 32, "a.png", x_m=1.0, y_m=2.0, heading_deg=90.0)
        map_db.add_place(place, [Fingerprint.empty("sift", 96, 24)])
    return db_path


def test_robot_specs() -> None:
    assert parse_robot_spec("sim") == ("sim", None)
    assert parse_robot_spec("p2os-sim") == ("p2os-sim", None)
    assert parse_robot_spec("p2os:/dev/ttyUSB0") == ("p2os", "/dev/ttyUSB0")
    for bad in ("p2os:", "pioneer", ""):
        with pytest.raises(ValueError, match=re.escape("a robot is sim | p2os-sim | p2os:PORT")):
            parse_robot_spec(bad)


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
        assert process.returncode == 0 and out.strip().endswith("stopped")
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
