"""``toploc serve --config FILE.toml``: the options from a TOML file, the command line winning;
bad files refused in one line; and a real ``serve`` from a file, logging at INFO."""

from __future__ import annotations

import os
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from bus_helpers import free_endpoint
from click.testing import CliRunner

from mapdb.database import MapDatabase
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.world import Pose2D
from robot.worlds import make_world
from toploc import bus
from toploc.cli import main
from toploc.commands.serve import serve
from toploc.nodes.camera import encode_png
from toploc.nodes.mapdb import MapClient

REPO = Path(__file__).resolve().parents[2]


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "serve.toml"
    path.write_text(text, encoding="utf-8")
    return path


def options(*args: str) -> dict:
    """The parameters ``toploc serve ARGS`` would run with (parsed by click, not run)."""
    with serve.make_context("serve", list(args)) as ctx:
        return dict(ctx.params)


def test_the_file_sets_options_and_the_command_line_wins(tmp_path):
    config = write(tmp_path, 'robot-id = "from-file"\npolicy = "most-likely"\nseed = 7\n')
    from_file = options("--config", str(config))
    assert (from_file["robot_id"], from_file["policy"], from_file["seed"]) == (
        "from-file", "most-likely", 7,
    )  # fmt: skip
    overridden = options("--config", str(config), "--robot-id", "from-flag")
    assert (overridden["robot_id"], overridden["policy"]) == ("from-flag", "most-likely")


def test_flags_lists_and_paths_relative_to_the_file(tmp_path):
    (tmp_path / "limits.toml").write_text("max_forward_m = 1.0\n")
    config = write(
        tmp_path,
        'db = "maps/home.db"\nnew-map = true\nno-sim = true\nlimits = "limits.toml"\n'
        'listen = ["tcp/127.0.0.1:7500", "tcp/127.0.0.1:7501"]\nmode = "router"\n',
    )
    params = options("--config", str(config))
    assert params["db_path"] == tmp_path / "maps" / "home.db"
    assert params["limits_path"] == tmp_path / "limits.toml"
    assert params["new_map"] and params["no_sim"]
    assert params["listen"] == ("tcp/127.0.0.1:7500", "tcp/127.0.0.1:7501")
    assert params["mode"] == "router"
    assert options("--config", str(config), "--listen", "tcp/127.0.0.1:7600")["listen"] == (
        "tcp/127.0.0.1:7600",
    )


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('robot_id = "r1"', "unknown key 'robot_id' (did you mean 'robot-id'?); known: "),
        ('colour = "red"', "unknown key 'colour'; known: camera, connect, db, limits"),
        ('seed = "one"', "key 'seed': expected an integer, got 'one'"),
        ("seed = true", "key 'seed': expected an integer, got True"),
        ("no-sim = 1", "key 'no-sim': expected true or false, got 1"),
        ('listen = "tcp/127.0.0.1:7447"', "key 'listen': expected a list, each item a string, got"),
        ('policy = "fastest"', "key 'policy': 'fastest' is not one of 'most-likely', 'separat"),
        ('robot-id = "a/b"', "key 'robot-id': robot id must be a non-empty key chunk"),
        ('limits = "missing.toml"', "key 'limits': File "),
        ("[serve]\nseed = 1", "unknown key 'serve'"),
        ("seed = ", "cannot read the config (Invalid value"),
    ],
)
def test_a_bad_file_is_refused_in_one_line_naming_the_file_and_key(tmp_path, text, message):
    config = write(tmp_path, text + "\n")
    done = CliRunner().invoke(main, ["serve", "--config", str(config)])
    assert done.exit_code == 1, done.output
    assert done.output.startswith(f"Error: {config}: ")
    assert message in done.output and done.output.count("\n") == 1, done.output


def test_a_missing_file_is_refused(tmp_path):
    done = CliRunner().invoke(main, ["serve", "--config", str(tmp_path / "nope.toml")])
    assert done.exit_code == 1
    assert done.output.startswith(f"Error: {tmp_path / 'nope.toml'}: cannot read the config")


class Serve:
    """A ``python -m toploc serve ...`` process; its stdout and stderr lines on queues."""

    def __init__(self, *args: str) -> None:
        env = {**os.environ, "PYTHONPATH": str(REPO), "PYTHONUNBUFFERED": "1"}
        self.process = subprocess.Popen(
            [sys.executable, "-m", "toploc", "serve", *args], cwd=REPO, env=env,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        self.stdout: queue.Queue[str] = queue.Queue()
        self.stderr: queue.Queue[str] = queue.Queue()
        self.output: list[str] = []
        for stream, lines in (
            (self.process.stdout, self.stdout),
            (self.process.stderr, self.stderr),
        ):
            threading.Thread(target=self._read, args=(stream, lines), daemon=True).start()

    def _read(self, stream, lines: queue.Queue[str]) -> None:
        for line in stream:
            self.output.append(line.rstrip())
            lines.put(line.rstrip())

    def wait_line(self, lines: queue.Queue[str], text: str, timeout_s: float = 30.0) -> str:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                line = lines.get(timeout=0.1)
            except queue.Empty:
                assert self.process.poll() is None, f"serve exited: {self.output}"
                continue
            if text in line:
                return line
        raise AssertionError(f"no line with {text!r} after {timeout_s} s: {self.output}")

    def stop(self) -> int:
        if self.process.poll() is None:
            self.process.terminate()
        try:
            return self.process.wait(20)
        except subprocess.TimeoutExpired:
            self.process.kill()
            return self.process.wait()


def test_serve_runs_from_a_file_and_logs_a_map_add_at_info(tmp_path):
    endpoint = free_endpoint()
    config = write(
        tmp_path,
        f'robot-id = "from-file"\nlisten = ["{endpoint}"]\ndb = "new.db"\nnew-map = true\n'
        'no-sim = true\npolicy = "most-likely"\n',
    )
    service = Serve("--config", str(config), "--robot-id", "from-flag")
    try:
        ready = service.wait_line(service.stdout, "Ctrl-C stops.")
        assert f"toploc/from-flag/** (peer, listen ['{endpoint}']" in ready
        assert str(tmp_path / "new.db") in ready
        world = make_world("building")
        pose = world.building_pose("kitchen", Pose2D(2.2, 2.9, 0.5))
        image = SimulatedRobot(world, pose, camera=PanoramaCamera(512, 96)).capture().image
        cfg = bus.BusConfig("from-flag", listen=(), connect=(endpoint,))
        with bus.open_session(cfg) as session:
            added = MapClient(session, "from-flag").add(encode_png(image), "kitchen")
        logged = service.wait_line(service.stderr, "map add:")
        assert logged.endswith(
            f" INFO toploc.nodes.mapdb: map add: place {added['place_id']} in room kitchen "
            f"(new; features sift {added['fingerprints']['sift']})"
        )
    finally:
        service.stop()
    with MapDatabase.open(tmp_path / "new.db", readonly=True) as map_db:
        assert [place.room for place in map_db.places()] == ["kitchen"]


def test_the_example_in_the_help_is_a_valid_config(tmp_path):
    assert serve.help is not None
    example = serve.help.split("\b\n", 1)[1].split("\n\n", 1)[0]  # the block, not what follows
    (tmp_path / "limits.toml").write_text("max_forward_m = 1.0\n")
    params = options("--config", str(write(tmp_path, "\n".join(
        line.strip() for line in example.splitlines()
    ))))  # fmt: skip
    assert (params["robot_id"], params["policy"], params["source"]) == (
        "kitchen-bot", "most-likely", "uvc:0",
    )  # fmt: skip


@pytest.mark.parametrize("command", ["robot", "camera", "localizer", "map", "ros2"])
def test_every_node_takes_its_options_from_a_file_and_refuses_an_unknown_key(tmp_path, command):
    config = write(tmp_path, "no-such-option = 1\n")
    done = CliRunner().invoke(main, ["node", command, "--config", str(config)])
    assert done.exit_code == 1, done.output
    assert done.output.startswith(f"Error: {config}: unknown key 'no-such-option'; known: ")


def test_a_map_node_reads_its_map_and_id_from_the_file(tmp_path):
    from toploc.commands.node import map_node

    config = write(tmp_path, 'db = "site.db"\nmap-id = "site-1"\nnew-map = true\n')
    with map_node.make_context("map", ["--config", str(config)]) as ctx:
        params = dict(ctx.params)
    assert (params["db_path"], params["map_id"], params["new_map"]) == (
        tmp_path / "site.db",
        "site-1",
        True,
    )
