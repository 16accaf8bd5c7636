"""A robot-side simulator of a Pioneer base that speaks P2OS/ARCOS on a pseudo-terminal.

It opens a pty (``os.openpty``), so a client opens :attr:`P2osSimulator.port` (or the stable
symlink ``link``) like a serial port. It answers the handshake (SYNC0 and SYNC1 echoed, SYNC2
answered with the robot's name, class and subclass strings, as ARIA reads them; the subclass is
``model``, and its SIPs are in that model's units), then OPEN,
ENABLE, PULSE, CLOSE, VEL, RVEL, HEAD, DHEAD and STOP. A unicycle integrates the commands every
``cycle_s`` (wall seconds; ``time_scale`` simulated seconds per wall second) in a rendered world:
the true pose is in the building frame, a disc of ``radius_m`` stops at walls and furniture
(:meth:`robot.sim_robot.Obstacles.reach_m`), which sets the bumper bits on the side it drove
and the stall bits, and stops the wheels. After OPEN a standard SIP goes out every cycle, its
position from the wheel odometry (exact: no slip), which starts at (0, 0, 0) when the simulator
starts. Its watchdog stops the wheels when no command has come for ``watchdog_s`` wall seconds.

Frame note: SYNC0, SYNC1 and SYNC2 are the same bytes as PULSE, OPEN and CLOSE; like the
firmware, the simulator reads them by its state (handshake or open).

Faults (:class:`SimFaults`, changeable while it runs): a mute handshake (the client's sync times
out), garbage bytes, truncated SIPs, SIPs with a bad checksum; and :meth:`P2osSimulator.vanish`
/ :meth:`P2osSimulator.reappear`: the pty closes (the client's reads and writes fail) and a new
one opens, its path re-pointed by the ``link`` symlink (a pty's path changes on reopen, as a USB
adapter's ``/dev/ttyUSBn`` may).
"""

from __future__ import annotations

import contextlib
import math
import os
import select
import threading
import time
import tty
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from homing.bearings import wrap_angle_rad
from localizer.robot_protocol import Pose2D
from robot.p2os_models import DEFAULT_MODEL, factors_for_model
from robot.p2os_protocol import (
    POSITION_WRAP,
    SYNC0,
    SYNC1,
    SYNC2,
    Command,
    CommandPacket,
    FrameParser,
    StandardSipRaw,
    encode_frame,
    encode_standard_sip,
    parse_command,
)
from robot.sim_robot import Obstacles
from robot.world import World

FRONT_BUMPERS = 0b01110
"""The bumper bits a head-on contact presses (a Pioneer 3 has five segments front and rear)."""
ROBOT_NAME = b"toploc-sim"
"""The name sent in the SYNC2 reply (then the class ``Pioneer`` and the model's subclass)."""


@dataclass
class SimFaults:
    """Faults to inject; changeable while the simulator runs. ``*_every``: every n-th SIP
    (0: never)."""

    mute_handshake: bool = False
    garbage_every: int = 0
    truncate_every: int = 0
    bad_checksum_every: int = 0


@dataclass
class _State:
    """The base's state (guarded by the simulator's lock)."""

    pose: Pose2D  # true, building frame
    odom_x_m: float = 0.0
    odom_y_m: float = 0.0
    odom_heading_rad: float = 0.0
    vel_m_s: float = 0.0  # commanded
    rvel_rad_s: float = 0.0  # commanded (when no heading target)
    heading_target_rad: float | None = None  # odometry heading (HEAD/DHEAD)
    motors_enabled: bool = False
    front_bumpers: int = 0
    rear_bumpers: int = 0
    stalled: bool = False
    measured_vel_m_s: float = 0.0
    measured_rvel_rad_s: float = 0.0


class P2osSimulator:
    """The simulated base on a pty; ``start()`` runs it on a thread, ``close()`` ends it."""

    def __init__(
        self,
        world: World,
        pose: Pose2D,
        *,
        radius_m: float = 0.2,
        cycle_s: float = 0.1,
        time_scale: float = 1.0,
        watchdog_s: float = 2.0,
        max_vel_m_s: float = 1.2,
        max_rvel_rad_s: float = math.radians(100.0),
        turn_rate_rad_s: float = math.radians(60.0),
        axle_m: float = 0.33,
        link: Path | None = None,
        faults: SimFaults | None = None,
        seed: int = 0,
        model: str = DEFAULT_MODEL,
    ) -> None:
        if not (cycle_s > 0 and time_scale > 0 and watchdog_s > 0):
            raise ValueError(
                f"cycle_s, time_scale and watchdog_s must be positive, got {cycle_s}, "
                f"{time_scale}, {watchdog_s}"
            )
        self.obstacles = Obstacles.of(world, radius_m)
        if not self.obstacles.free(np.array([[pose.x_m, pose.y_m]]))[0]:
            raise ValueError(
                f"starting pose ({pose.x_m}, {pose.y_m}) m is not free in world {world.name!r}"
            )
        self.world = world
        self.model = model.strip().lower()
        """The subclass the SYNC2 reply names; SIPs are in its units (ARIA's factors)."""
        self.factors = factors_for_model(self.model)
        self.cycle_s = cycle_s
        self.time_scale = time_scale
        self.watchdog_s = watchdog_s
        self.max_vel_m_s = max_vel_m_s
        self.max_rvel_rad_s = max_rvel_rad_s
        self.turn_rate_rad_s = turn_rate_rad_s
        self.axle_m = axle_m
        self.link = link
        self.faults = faults or SimFaults()
        self.received: list[CommandPacket] = []
        """Every command frame received, in order (after the handshake)."""
        self.sips_sent = 0
        self.watchdog_stops = 0
        self.phase = "sync0"
        """``sync0``, ``sync1``, ``sync2`` (handshake), ``ready`` (synced), ``open`` (SIPs)."""
        self._state = _State(Pose2D(pose.x_m, pose.y_m, float(wrap_angle_rad(pose.heading_rad))))
        self._lock = threading.Lock()
        self._rng = np.random.default_rng(seed)
        self._parser = FrameParser()
        self._master: int | None = None
        self._slave: int | None = None
        self._port = ""
        self._last_command_s = time.monotonic()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._open_pty()

    # -- the pty ------------------------------------------------------------------------------

    @property
    def port(self) -> str:
        """The path to open: the ``link`` symlink if given, else the pty's own path."""
        return str(self.link) if self.link is not None else self._port

    def _open_pty(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no line editing: bytes pass as they are
        os.set_blocking(master, False)  # a client that does not read must not block us
        with self._lock:
            self._master, self._slave = master, slave
            self._port = os.ttyname(slave)
            self._parser = FrameParser()
            self.phase = "sync0"
        if self.link is not None:
            tmp = self.link.with_name(self.link.name + ".tmp")
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
            tmp.symlink_to(self._port)
            tmp.replace(self.link)

    def vanish(self) -> None:
        """The port disappears: the pty closes (and ``link`` is removed)."""
        with self._lock:
            fds = (self._master, self._slave)
            self._master = self._slave = None
            self.phase = "sync0"
        if self.link is not None:
            with contextlib.suppress(FileNotFoundError):
                self.link.unlink()
        for fd in fds:
            if fd is not None:
                os.close(fd)

    def reappear(self) -> None:
        """The port comes back: a new pty (a new path; ``link`` points at it)."""
        self._open_pty()

    # -- running ------------------------------------------------------------------------------

    def start(self) -> P2osSimulator:
        """Run on a daemon thread; returns self."""
        self._thread = threading.Thread(target=self.run, name="p2os-sim", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the thread and close the pty."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        self.vanish()

    def __enter__(self) -> P2osSimulator:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def run(self) -> None:
        """Read commands and step the base every ``cycle_s`` until :meth:`close`."""
        next_tick = last = time.monotonic()
        while not self._stop.is_set():
            master = self._master
            wait = max(0.0, next_tick - time.monotonic())
            if master is None:
                time.sleep(wait)
            else:
                try:
                    ready, _, _ = select.select([master], [], [], wait)
                    data = os.read(master, 4096) if ready else b""
                except OSError:  # closed by vanish(), or no slave left
                    data = b""
                for payload in self._parser.feed(data):
                    self._handle(payload)
            now = time.monotonic()
            if now >= next_tick:
                self._step((now - last) * self.time_scale, now)
                last = now
                next_tick = max(next_tick + self.cycle_s, now)
                if self.phase == "open":
                    self._send_sip()

    @property
    def true_pose(self) -> Pose2D:
        """The base's true pose in the building frame."""
        with self._lock:
            return self._state.pose

    def teleport(self, pose: Pose2D) -> None:
        """Put the base at ``pose`` (building frame) at once, the wheels stopped, as a person
        carrying it would (a kidnap): the odometry is not told. ``ValueError`` if the pose is
        not free."""
        if not self.obstacles.free(np.array([[pose.x_m, pose.y_m]]))[0]:
            raise ValueError(f"pose ({pose.x_m}, {pose.y_m}) m is not free in {self.world.name!r}")
        with self._lock:
            s = self._state
            s.pose = Pose2D(pose.x_m, pose.y_m, float(wrap_angle_rad(pose.heading_rad)))
            s.vel_m_s = s.rvel_rad_s = 0.0
            s.heading_target_rad = None
            s.front_bumpers = s.rear_bumpers = 0
            s.stalled = False

    def commands(self) -> list[int]:
        """The command numbers received so far, in order."""
        with self._lock:
            return [c.command for c in self.received]

    def moving(self) -> bool:
        """Whether the wheels turn (as the last step measured)."""
        with self._lock:
            s = self._state
            return s.measured_vel_m_s != 0.0 or s.measured_rvel_rad_s != 0.0

    # -- commands -----------------------------------------------------------------------------

    def _write(self, data: bytes) -> None:
        master = self._master
        if master is None:
            return
        with contextlib.suppress(BlockingIOError, OSError):  # full (nobody reads) or gone
            os.write(master, data)

    def _handle(self, payload: bytes) -> None:
        try:
            cmd = parse_command(payload)
        except ValueError:
            return
        n = cmd.command
        if self.phase != "open":
            self._handshake(cmd)
            return
        self._last_command_s = time.monotonic()
        with self._lock:
            self.received.append(cmd)
            s = self._state
            arg = cmd.arg if isinstance(cmd.arg, int) else 0
            if n == Command.CLOSE:
                self.phase = "sync0"
                s.vel_m_s = s.rvel_rad_s = 0.0
                s.heading_target_rad = None
                s.motors_enabled = False
            elif n == Command.ENABLE:
                s.motors_enabled = bool(arg)
            elif n == Command.STOP:
                s.vel_m_s = s.rvel_rad_s = 0.0
                s.heading_target_rad = None
            elif n == Command.VEL and s.motors_enabled:
                s.vel_m_s = float(np.clip(arg / 1000.0, -self.max_vel_m_s, self.max_vel_m_s))
            elif n == Command.RVEL and s.motors_enabled:
                s.rvel_rad_s = float(
                    np.clip(math.radians(arg), -self.max_rvel_rad_s, self.max_rvel_rad_s)
                )
                s.heading_target_rad = None
            elif n == Command.HEAD and s.motors_enabled:
                s.heading_target_rad = float(wrap_angle_rad(math.radians(arg)))
            elif n == Command.DHEAD and s.motors_enabled:
                s.heading_target_rad = float(wrap_angle_rad(s.odom_heading_rad + math.radians(arg)))

    def _handshake(self, cmd: CommandPacket) -> None:
        if self.faults.mute_handshake:
            return
        n, phase = cmd.command, self.phase
        if n == SYNC0 and cmd.arg is None:
            self.phase = "sync1"
            self._write(encode_frame(bytes([SYNC0])))
        elif n == SYNC1 and phase in ("sync1", "sync2"):
            self.phase = "sync2"
            self._write(encode_frame(bytes([SYNC1])))
        elif n == SYNC2 and phase == "sync2":
            self.phase = "ready"
            strings = (ROBOT_NAME, b"Pioneer", self.model.encode("ascii"))
            self._write(encode_frame(bytes([SYNC2]) + b"".join(s + b"\0" for s in strings)))
        elif n == Command.OPEN and phase == "ready":
            self.phase = "open"
            self._last_command_s = time.monotonic()
            with self._lock:
                self.received.append(cmd)

    # -- the unicycle -------------------------------------------------------------------------

    def _step(self, dt_s: float, now_s: float) -> None:
        with self._lock:
            s = self._state
            if now_s - self._last_command_s > self.watchdog_s and (
                s.vel_m_s or s.rvel_rad_s or s.heading_target_rad is not None
            ):
                s.vel_m_s = s.rvel_rad_s = 0.0
                s.heading_target_rad = None
                self.watchdog_stops += 1
            if not s.motors_enabled:
                s.vel_m_s = s.rvel_rad_s = 0.0
                s.heading_target_rad = None
            if s.heading_target_rad is not None:
                err = float(wrap_angle_rad(s.heading_target_rad - s.odom_heading_rad))
                limit = self.turn_rate_rad_s * dt_s
                dth = float(np.clip(err, -limit, limit))
            else:
                dth = s.rvel_rad_s * dt_s
            heading = float(wrap_angle_rad(s.pose.heading_rad + dth))
            s.odom_heading_rad = float(wrap_angle_rad(s.odom_heading_rad + dth))
            want = s.vel_m_s * dt_s
            driven, bumped = 0.0, False
            if want:
                driven, bumped = self.obstacles.reach_m(s.pose, heading, want)
                if driven:
                    s.front_bumpers = s.rear_bumpers = 0
                if bumped:
                    s.vel_m_s = 0.0  # the firmware stops the wheels on contact
                    if want > 0:
                        s.front_bumpers = FRONT_BUMPERS
                    else:
                        s.rear_bumpers = FRONT_BUMPERS
            s.stalled = bumped
            s.pose = Pose2D(
                s.pose.x_m + driven * math.cos(heading),
                s.pose.y_m + driven * math.sin(heading),
                heading,
            )
            s.odom_x_m += driven * math.cos(s.odom_heading_rad)
            s.odom_y_m += driven * math.sin(s.odom_heading_rad)
            s.measured_vel_m_s = driven / dt_s if dt_s > 0 else 0.0
            s.measured_rvel_rad_s = dth / dt_s if dt_s > 0 else 0.0

    def _sip(self) -> StandardSipRaw:
        with self._lock:
            s = self._state
            f = self.factors
            v, w = s.measured_vel_m_s, s.measured_rvel_rad_s
            left = round((v - w * self.axle_m / 2) * 1000.0 / f.mm_s_per_vel_unit)
            right = round((v + w * self.axle_m / 2) * 1000.0 / f.mm_s_per_vel_unit)
            units = round(s.odom_heading_rad / (2 * math.pi) * f.angle_units_per_rev)
            return StandardSipRaw(
                moving=bool(v or w),
                x_counts=round(s.odom_x_m * 1000.0 / f.mm_per_count) % POSITION_WRAP,
                y_counts=round(s.odom_y_m * 1000.0 / f.mm_per_count) % POSITION_WRAP,
                heading_units=units % f.angle_units_per_rev,
                left_vel_units=int(np.clip(left, -32768, 32767)),
                right_vel_units=int(np.clip(right, -32768, 32767)),
                battery_decivolts=128,
                left_stall=s.stalled,
                right_stall=s.stalled,
                rear_bumpers=s.rear_bumpers,
                front_bumpers=s.front_bumpers,
                flags=int(s.motors_enabled),
            )

    def _send_sip(self) -> None:
        self.sips_sent += 1
        n, f = self.sips_sent, self.faults
        frame = encode_frame(encode_standard_sip(self._sip()))
        if f.garbage_every and n % f.garbage_every == 0:
            noise = self._rng.integers(0, 256, int(self._rng.integers(1, 40)), dtype=np.uint8)
            self._write(noise.tobytes() + b"\xfa\xfb\x09\x33")  # noise and a false header
        if f.bad_checksum_every and n % f.bad_checksum_every == 0:
            frame = frame[:-1] + bytes([frame[-1] ^ 0x5A])
        if f.truncate_every and n % f.truncate_every == 0:
            frame = frame[: len(frame) // 2]
        self._write(frame)
