"""P2osBase against the P2OS simulator over a real pseudo-terminal: handshake, moves, bumpers,
faults (sync timeout, garbage, truncated frames, bad checksums, a vanishing port), watchdog."""

from __future__ import annotations

import dataclasses
import math
import re
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import serial

from homing.bearings import wrap_angle_rad
from localizer.robot_protocol import Pose2D
from robot.p2os_base import P2osBase, P2osError, P2osSettings
from robot.p2os_models import factors_for_model, factors_from_sync
from robot.p2os_protocol import (
    Command,
    FrameParser,
    enable_frame,
    open_frame,
    pulse_frame,
    sync_frame,
    vel_frame,
)
from robot.p2os_robot import BaseWithCamera, SimCamera
from robot.p2os_sim import P2osSimulator, SimFaults
from robot.render import PanoramaCamera, render_panorama
from robot.world import World
from robot.worlds import make_world

START = Pose2D(6.0, 3.9, 0.0)  # office_b of `building`: x 4-8 m, y 2.2-5.6 m
FAST = P2osSettings(sync_timeout_s=1.0, sip_timeout_s=0.5, reconnect_s=0.05, max_reconnect_s=0.2)


@pytest.fixture(scope="module")
def world() -> World:
    return make_world("building")


def simulator(world: World, **kwargs) -> P2osSimulator:
    """A fast simulator (4x time, SIPs every 50 ms) on a new pty, running."""
    options = {"time_scale": 4.0, "cycle_s": 0.05, **kwargs}
    return P2osSimulator(world, START, **options).start()


@pytest.fixture
def sim(world: World) -> Iterator[P2osSimulator]:
    s = simulator(world)
    yield s
    s.close()


@pytest.fixture
def base(sim: P2osSimulator) -> Iterator[P2osBase]:
    b = P2osBase(sim.port, settings=FAST)
    b.connect()
    yield b
    b.close()


def test_handshake_names_the_robot_and_opens(sim: P2osSimulator, base: P2osBase) -> None:
    assert base.robot_strings == ("toploc-sim", "Pioneer", "p3dx-sh")
    assert sim.phase == "open"
    assert [c.command for c in sim.received[:2]] == [Command.OPEN, Command.ENABLE]
    assert sim.received[1].arg == 1
    assert base.odometry().x_m == 0.0 and base.latest_sip() is not None


def test_turn_then_drive_ends_near_the_commanded_pose(sim: P2osSimulator, base: P2osBase) -> None:
    result = base.move(math.pi / 2, 0.5)
    assert not result.bumped
    assert result.turned_rad == pytest.approx(math.pi / 2, abs=math.radians(2))
    assert result.moved_m == pytest.approx(0.5, abs=0.03)
    odom = base.odometry()
    assert (odom.x_m, odom.y_m) == pytest.approx((0.0, 0.5), abs=0.03)
    assert odom.heading_rad == pytest.approx(math.pi / 2, abs=math.radians(2))
    truth = sim.true_pose
    assert (truth.x_m, truth.y_m) == pytest.approx((START.x_m, START.y_m + 0.5), abs=0.03)
    # the manual's commands: DHEAD by the turn, then VEL forward (slowing down), then STOP
    motion = [c for c in sim.received if c.command != Command.PULSE][2:]
    assert motion[0].command == Command.DHEAD and motion[0].arg == 90
    vels = [c.arg for c in motion if c.command == Command.VEL]
    assert vels and all(isinstance(v, int) and 0 < v <= 400 for v in vels)
    assert vels[-1] < vels[0]
    assert motion[-1].command == Command.STOP


def test_a_negative_turn_and_a_drive_backwards(sim: P2osSimulator, base: P2osBase) -> None:
    result = base.move(-math.pi / 4, -0.3)
    assert result.turned_rad == pytest.approx(-math.pi / 4, abs=math.radians(2))
    assert result.moved_m == pytest.approx(-0.3, abs=0.03)
    truth = sim.true_pose
    expected = (START.x_m - 0.3 * math.cos(-math.pi / 4), START.y_m - 0.3 * math.sin(-math.pi / 4))
    assert (truth.x_m, truth.y_m) == pytest.approx(expected, abs=0.03)


def test_bumper_stops_backs_off_and_reports_bumped(sim: P2osSimulator, base: P2osBase) -> None:
    result = base.move(math.pi / 2, 3.0)  # the wall at y = 5.6 m, radius 0.2 m: 1.5 m away
    assert result.bumped
    assert result.moved_m == pytest.approx(1.5 - 0.1, abs=0.04)
    assert sim.true_pose.y_m == pytest.approx(5.4 - 0.1, abs=0.04)
    vels = [c.arg for c in sim.received if c.command == Command.VEL]
    assert vels[-1] < 0 and min(vels) == -100  # backed off at (up to) 0.1 m/s
    assert not sim.moving()


def test_stop_from_another_thread_ends_a_move(sim: P2osSimulator, base: P2osBase) -> None:
    threading.Timer(0.4, base.stop).start()
    started = time.monotonic()
    result = base.move(math.pi, 3.0)
    assert time.monotonic() - started < 1.5
    assert not result.bumped and result.moved_m < 3.0
    time.sleep(0.2)
    assert not sim.moving()


def test_sync_timeout_is_a_quick_error_naming_the_port(world: World) -> None:
    sim = simulator(world, faults=SimFaults(mute_handshake=True))
    try:
        base = P2osBase(sim.port, settings=P2osSettings(sync_timeout_s=0.4))
        started = time.monotonic()
        with pytest.raises(P2osError, match=re.escape(f"no answer to SYNC0 from {sim.port}")):
            base.connect()
        assert time.monotonic() - started < 1.0
    finally:
        sim.close()


def test_a_port_that_does_not_exist(tmp_path: Path) -> None:
    port = str(tmp_path / "ttyUSB9")
    with pytest.raises(P2osError, match=re.escape(f"cannot open serial port {port}")):
        P2osBase(port).connect()


def test_garbage_truncated_frames_and_bad_checksums_are_skipped(world: World) -> None:
    faults = SimFaults(garbage_every=2, truncate_every=5, bad_checksum_every=3)
    sim = simulator(world, faults=faults)
    try:
        with P2osBase(sim.port, settings=FAST) as base:
            result = base.move(math.pi / 2, 0.5)
            assert not result.bumped
            assert result.moved_m == pytest.approx(0.5, abs=0.04)
            assert base.parser.skipped_bytes > 0
            assert base.parser.bad_checksums > 0
            assert base.parser.frames > 0
    finally:
        sim.close()


def raw_open(port: str) -> serial.Serial:
    """A bare client: handshake, OPEN, ENABLE 1, as the manual has it."""
    link = serial.Serial(port, 9600, timeout=0.5)
    parser = FrameParser()
    for n in range(3):
        link.write(sync_frame(n))
        deadline = time.monotonic() + 1.0
        got: list[bytes] = []
        while not got and time.monotonic() < deadline:
            got = parser.feed(link.read(max(1, link.in_waiting)))
        assert got and got[0][0] == n
    link.write(open_frame() + enable_frame(True))
    return link


def test_the_watchdog_stops_the_robot_when_the_client_falls_silent(world: World) -> None:
    sim = simulator(world, watchdog_s=0.5)
    try:
        link = raw_open(sim.port)
        link.write(vel_frame(100))
        for _ in range(6):  # PULSEs keep it going past the watchdog's time
            time.sleep(0.2)
            link.write(pulse_frame())
        assert sim.moving() and sim.watchdog_stops == 0
        time.sleep(0.8)  # silence
        assert not sim.moving()
        assert sim.watchdog_stops == 1
        link.close()
    finally:
        sim.close()


def test_the_base_sends_pulses(sim: P2osSimulator) -> None:
    with P2osBase(sim.port, settings=P2osSettings(pulse_s=0.1)):
        time.sleep(0.5)
    deadline = time.monotonic() + 5.0  # the simulator reads the closing frames on its thread
    while sim.phase != "sync0" and time.monotonic() < deadline:
        time.sleep(0.01)
    assert sim.commands().count(Command.PULSE) >= 3
    assert sim.commands()[-3:] == [Command.STOP, Command.ENABLE, Command.CLOSE]
    assert sim.phase == "sync0"


def _reconnected_odometry(base: P2osBase, timeout_s: float = 10.0) -> Pose2D:
    """The base's odometry once it has reconnected: each call within the reconnect backoff,
    or whose handshake the loaded machine answered too late, raises and is asked again."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return base.odometry()
        except P2osError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)


def test_a_vanished_port_is_an_error_then_a_reconnect(world: World, tmp_path: Path) -> None:
    link = tmp_path / "pioneer"
    sim = simulator(world, link=link)
    try:
        # the handshake on the new pty may wait on a loaded machine (CI: 1 s once ran out)
        base = P2osBase(str(link), settings=dataclasses.replace(FAST, sync_timeout_s=5.0))
        base.connect()
        base.move(0.0, 0.3)
        before = base.odometry()
        sim.vanish()
        started = time.monotonic()
        with pytest.raises(P2osError, match=re.escape(str(link))):
            base.move(0.0, 0.3)
        with pytest.raises(P2osError, match=re.escape(str(link))):  # still gone: quick, no hang
            base.odometry()
        assert time.monotonic() - started < 2.0
        sim.reappear()
        after = _reconnected_odometry(base)  # a fresh handshake on the new pty
        assert (after.x_m, after.y_m) == pytest.approx((before.x_m, before.y_m), abs=0.01)
        result = base.move(0.0, 0.3)
        assert result.moved_m == pytest.approx(0.3, abs=0.03)
        assert base.odometry().x_m == pytest.approx(0.6, abs=0.05)
        base.close()
    finally:
        sim.close()


def test_a_client_that_crashed_is_closed_and_resynced(sim: P2osSimulator) -> None:
    """A base left open by a crashed client sends SIPs, not echoes: CLOSE, then sync again."""
    raw_open(sim.port).close()  # never sent CLOSE
    time.sleep(0.2)
    assert sim.phase == "open"
    with P2osBase(sim.port, settings=FAST) as base:
        assert base.robot_strings[0] == "toploc-sim"


def test_base_with_sim_camera_renders_at_the_true_pose(
    world: World, sim: P2osSimulator, base: P2osBase
) -> None:
    camera = PanoramaCamera(128, 24, height_m=world.camera_height_m)
    sim_camera = SimCamera(world, lambda: sim.true_pose, camera, grey=True)
    robot = BaseWithCamera(base, sim_camera)
    robot.move(math.pi / 2, 0.4)
    shot = robot.capture()
    expected = render_panorama(sim_camera._scene, sim.true_pose, camera, seed=(0, 17, 0), grey=True)
    assert np.array_equal(shot.image, expected)
    assert robot.odometry().y_m == pytest.approx(0.4, abs=0.03)


def test_a_second_client_cannot_open_a_port_in_use(sim: P2osSimulator, base: P2osBase) -> None:
    """Two toploc processes on one base would both drive it: the port is opened exclusively."""
    second = P2osBase(sim.port, settings=FAST)
    with pytest.raises(P2osError, match=f"cannot open serial port {sim.port}"):
        second.connect()
    assert [c.command for c in sim.received].count(Command.OPEN) == 1  # the first one's only


@pytest.mark.parametrize("turn_deg", [180.0, -180.0, 179.9, -179.9, 0.0, 360.0, -360.0])
def test_a_turn_ends_at_its_heading_whichever_way_the_base_turned(
    sim: P2osSimulator, base: P2osBase, turn_deg: float
) -> None:
    """+180 and -180 deg are one heading: the firmware may take either way round (issue 23)."""
    expected_rad = float(wrap_angle_rad(math.radians(turn_deg)))
    result = base.move(math.radians(turn_deg), 0.0)
    tolerance_rad = math.radians(2.5)
    assert abs(wrap_angle_rad(result.turned_rad - expected_rad)) < tolerance_rad
    assert abs(wrap_angle_rad(base.odometry().heading_rad - expected_rad)) < tolerance_rad
    assert abs(wrap_angle_rad(sim.true_pose.heading_rad - expected_rad)) < tolerance_rad


@pytest.mark.parametrize("start_deg", [17.0, -123.0])
def test_a_half_turn_from_any_heading_ends_behind_the_robot(
    sim: P2osSimulator, base: P2osBase, start_deg: float
) -> None:
    base.move(math.radians(start_deg), 0.0)
    before_rad = base.odometry().heading_rad
    for turn_deg in (180.0, -180.0):
        result = base.move(math.radians(turn_deg), 0.0)
        assert abs(abs(result.turned_rad) - math.pi) < math.radians(2.5)
        after_rad = base.odometry().heading_rad
        assert abs(wrap_angle_rad(after_rad - before_rad - math.pi)) < math.radians(2.5)
        before_rad = after_rad


def test_a_classic_p3dx_is_read_in_its_own_units(world: World) -> None:
    """A P3-DX without the SH controller counts 0.485 mm (ARIA's p3dx.p): told to drive 0.3 m,
    it drives 0.3 m, and its odometry says so."""
    sim = simulator(world, model="p3dx")
    try:
        with P2osBase(sim.port, settings=FAST) as base:
            assert base.robot_strings[2] == "p3dx"
            assert base.factors == factors_for_model("p3dx")
            result = base.move(0.0, 0.3)
            assert result.moved_m == pytest.approx(0.3, abs=0.03)
            assert base.odometry().x_m == pytest.approx(0.3, abs=0.03)
        assert sim.true_pose.x_m == pytest.approx(START.x_m + 0.3, abs=0.03)
    finally:
        sim.close()


def test_a_pioneer_1_turns_in_1024_heading_units(world: World) -> None:
    sim = simulator(world, model="pion1m")
    try:
        with P2osBase(sim.port, settings=FAST) as base:
            result = base.move(math.pi / 2, 0.2)
            assert result.turned_rad == pytest.approx(math.pi / 2, abs=math.radians(2.5))
            assert result.moved_m == pytest.approx(0.2, abs=0.03)
        assert sim.true_pose.y_m == pytest.approx(START.y_m + 0.2, abs=0.03)
    finally:
        sim.close()


def test_a_named_model_overrides_the_sync_reply(world: World) -> None:
    """A base whose SYNC2 names the wrong subclass can be told its model (p2os:PORT@p3dx)."""
    sim = simulator(world, model="p3dx")
    try:
        with P2osBase(sim.port, settings=FAST, model="p3dx-sh") as base:
            base.move(0.0, 0.3)  # its 0.485 mm counts read as 1 mm: it stops short
        assert sim.true_pose.x_m - START.x_m == pytest.approx(0.3 * 0.485, abs=0.03)
    finally:
        sim.close()


def test_an_unknown_model_is_read_as_a_p3dx_sh_with_a_warning(
    caplog: pytest.LogCaptureFixture,
) -> None:
    with caplog.at_level("WARNING"):
        factors = factors_from_sync(("robot", "Pioneer", "p9zz"), "/dev/ttyUSB0")
    assert factors == factors_for_model("p3dx-sh")
    assert "/dev/ttyUSB0: unknown Pioneer model 'p9zz'" in caplog.text
