"""A Pioneer base over its serial port (P2OS/ARCOS, pyserial): connect, turn, drive, odometry.

:class:`P2osBase` does the handshake (SYNC0, SYNC1, SYNC2, whose reply carries the robot's
name, class and subclass), OPEN and ENABLE 1; then a reader thread feeds the bytes to a
:class:`~robot.p2os_protocol.FrameParser` (garbage, truncated frames and bad checksums are
skipped and counted, :attr:`P2osBase.parser`) and keeps the latest SIP, and a PULSE goes out
every ``pulse_s`` so the firmware's watchdog (about 2 s) does not stop the robot.

A move is turn-then-drive (thesis 5.3.1): DHEAD by the turn (the firmware closes the heading
loop) until the odometry heading is within ``turn_tol_rad`` and the base has stopped turning;
then VEL, slowing down near the goal, until the odometry distance is reached, then STOP. A
bumper or stall flag ends the drive (thesis 5.3.2): STOP, back off ``backoff_m`` at
``backoff_m_s``, and the result says ``bumped``. :meth:`P2osBase.stop` (from another thread)
sends STOP and ends a move at once.

Odometry comes from the SIPs: the 15-bit positions unwrapped, in the odometry frame (REP-103),
(0, 0, 0) where the base first connected and continuous across reconnects.

Faults: every wait has a deadline, and a failure is a :class:`P2osError` naming the port. A
port that fails (unplugged: ``SerialException``/``OSError``) fails the call under way; the next
call reconnects (a fresh handshake), at most once per backoff interval (``reconnect_s``,
doubling up to ``max_reconnect_s``). While toploc does not talk (crashed, or the port gone), the
firmware's watchdog stops the robot.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from dataclasses import dataclass

import serial

from homing.bearings import wrap_angle_rad
from localizer.robot_protocol import MoveResult, Pose2D
from robot.p2os_models import factors_for_model, factors_from_sync
from robot.p2os_protocol import (
    SYNC0,
    SYNC2,
    ConversionFactors,
    FrameParser,
    SipType,
    StandardSip,
    StandardSipRaw,
    close_frame,
    decode_standard_sip,
    dhead_frame,
    enable_frame,
    open_frame,
    position_delta_counts,
    pulse_frame,
    sip_to_si,
    stop_frame,
    sync_frame,
    vel_frame,
)


class P2osError(RuntimeError):
    """The base failed or did not answer in time; the message names the port."""


@dataclass(frozen=True)
class P2osSettings:
    """Timeouts (seconds) and motion parameters (SI)."""

    sync_timeout_s: float = 3.0  # the whole handshake
    sync_retry_s: float = 0.3  # resend a SYNC frame not answered this long
    sip_timeout_s: float = 1.0  # no SIP for this long: the base is gone
    pulse_s: float = 1.0
    write_timeout_s: float = 1.0
    reconnect_s: float = 0.5
    max_reconnect_s: float = 8.0
    max_speed_m_s: float = 0.4
    min_speed_m_s: float = 0.05
    slowdown_per_s: float = 1.5  # speed = this x remaining distance, between min and max
    distance_tol_m: float = 0.01
    turn_tol_rad: float = math.radians(2.0)
    min_turn_rate_rad_s: float = math.radians(15.0)  # for the turn's deadline
    settle_s: float = 2.0  # slack in every motion deadline
    backoff_m: float = 0.1
    backoff_m_s: float = 0.1


class P2osBase:
    """The base of a Pioneer on serial port ``port`` (see the module docstring)."""

    def __init__(
        self,
        port: str,
        baud: int = 9600,
        settings: P2osSettings | None = None,
        model: str | None = None,
    ) -> None:
        self.port = port
        self.baud = baud
        self.settings = settings or P2osSettings()
        self.model = model
        """The Pioneer model whose units the SIPs are read in (e.g. ``p3dx``); None: the
        subclass the SYNC2 reply names (:mod:`robot.p2os_models`)."""
        self.factors: ConversionFactors = (
            factors_for_model(model) if model is not None else ConversionFactors()
        )
        """The conversion factors in use (set from the SYNC2 reply when ``model`` is None)."""
        self.robot_strings: tuple[str, ...] = ()
        """Name, class and subclass from the SYNC2 reply."""
        self.parser = FrameParser()
        self.bad_sips = 0
        self._ser: serial.Serial | None = None
        self._fault: P2osError | None = None
        self._conn_lock = threading.RLock()
        self._write_lock = threading.Lock()
        self._cond = threading.Condition()
        self._halt = threading.Event()  # per connection: ends the reader and pulse threads
        self._threads: list[threading.Thread] = []
        self._stop_move = threading.Event()
        self._next_attempt_s = 0.0
        self._backoff_s = self.settings.reconnect_s
        self._last_error: P2osError | None = None
        # odometry (guarded by _cond)
        self._seq = 0
        self._sip: StandardSip | None = None
        self._fw_prev: tuple[int, int] | None = None
        self._fw_xy_m = (0.0, 0.0)  # firmware position since this connection, unwrapped
        self._anchor = (0.0, 0.0, 0.0)  # odometry pose at this connection's first SIP
        self._fw_heading0 = 0.0
        self._odom = Pose2D(0.0, 0.0, 0.0)
        self._heading_total_rad = 0.0  # unwrapped heading

    # -- connection ---------------------------------------------------------------------------

    def connect(self) -> None:
        """Connect now (handshake, OPEN, ENABLE 1, first SIP); :class:`P2osError` if it fails."""
        with self._conn_lock:
            self._next_attempt_s = 0.0
            self.ensure_connected()

    def ensure_connected(self) -> None:
        """Reconnect if the port failed, at most once per backoff interval."""
        with self._conn_lock:
            if self._ser is not None and self._fault is None:
                return
            if self._ser is not None:
                self._teardown()
            now = time.monotonic()
            if now < self._next_attempt_s and self._last_error is not None:
                raise P2osError(
                    f"{self._last_error} (next reconnect in {self._next_attempt_s - now:.1f} s)"
                )
            try:
                self._connect_once()
            except P2osError as error:
                self._last_error = error
                self._next_attempt_s = time.monotonic() + self._backoff_s
                self._backoff_s = min(2 * self._backoff_s, self.settings.max_reconnect_s)
                raise
            self._backoff_s = self.settings.reconnect_s
            self._last_error = None

    def _connect_once(self) -> None:
        s = self.settings
        try:
            # exclusive: a second toploc (or anything else that asks) cannot drive this base too
            ser = serial.Serial(
                self.port, self.baud, timeout=0.05, write_timeout=s.write_timeout_s, exclusive=True
            )
        except (serial.SerialException, OSError, ValueError) as error:
            raise P2osError(f"cannot open serial port {self.port}: {error}") from error
        try:
            ser.reset_input_buffer()
            self.robot_strings = self._handshake(ser)
            if self.model is None:
                self.factors = factors_from_sync(self.robot_strings, self.port)
            ser.write(open_frame())
            ser.write(enable_frame(True))
        except (serial.SerialException, OSError) as error:
            ser.close()
            raise P2osError(f"serial port {self.port} failed during connect: {error}") from error
        except P2osError:
            ser.close()
            raise
        with self._cond:
            self._ser, self._fault, self._fw_prev = ser, None, None
        self._halt = threading.Event()
        self._threads = [
            threading.Thread(target=self._read_loop, args=(ser, self._halt), daemon=True),
            threading.Thread(target=self._pulse_loop, args=(self._halt,), daemon=True),
        ]
        for thread in self._threads:
            thread.start()
        try:
            self._next_sip(self._seq, interruptible=False)
        except P2osError:
            self._teardown()
            raise

    def _handshake(self, ser: serial.Serial) -> tuple[str, ...]:
        """SYNC0, SYNC1, SYNC2 (each answered by its echo); the SYNC2 reply's strings."""
        s = self.settings
        parser = FrameParser()
        deadline = time.monotonic() + s.sync_timeout_s
        expect, sent_s = SYNC0, 0.0
        while time.monotonic() < deadline:
            if time.monotonic() - sent_s > s.sync_retry_s:
                ser.write(sync_frame(expect))
                sent_s = time.monotonic()
            for payload in parser.feed(ser.read(max(1, ser.in_waiting))):
                if payload[0] in (SipType.STOPPED, SipType.MOVING):  # still open from before
                    ser.write(close_frame())
                    time.sleep(0.1)
                    ser.reset_input_buffer()
                    expect, sent_s = SYNC0, 0.0
                    break
                if payload[0] == expect == SYNC2:
                    strings = payload[1:].split(b"\0")[:3]
                    return tuple(t.decode("ascii", "replace") for t in strings)
                if payload[0] == expect:
                    expect, sent_s = expect + 1, 0.0
        raise P2osError(
            f"no answer to SYNC{expect} from {self.port} within {s.sync_timeout_s:g} s: is the "
            "robot on, and is this its port?"
        )

    def _teardown(self) -> None:
        """Stop the threads and close the port (after a fault, or on close)."""
        self._halt.set()
        for thread in self._threads:
            if thread is not threading.current_thread():
                thread.join(timeout=2.0)
        self._threads = []
        with self._cond:
            ser, self._ser = self._ser, None
            self._cond.notify_all()
        if ser is not None:
            with contextlib.suppress(serial.SerialException, OSError):
                ser.close()

    def close(self) -> None:
        """STOP, ENABLE 0 and CLOSE (best effort), then close the port."""
        with self._conn_lock:
            if self._ser is not None and self._fault is None:
                for frame in (stop_frame(), enable_frame(False), close_frame()):
                    try:
                        self._send(frame)
                    except P2osError:
                        break
            self._teardown()

    def __enter__(self) -> P2osBase:
        self.connect()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- I/O threads --------------------------------------------------------------------------

    def _fail(self, error: P2osError) -> None:
        with self._cond:
            if self._fault is None:
                self._fault = error
            self._cond.notify_all()

    def _send(self, frame: bytes) -> None:
        with self._write_lock:
            ser = self._ser
            if ser is None or self._fault is not None:
                raise self._fault or P2osError(f"serial port {self.port} is not connected")
            try:
                ser.write(frame)
            except (serial.SerialException, OSError) as error:
                fault = P2osError(f"serial port {self.port} failed: {error}")
                self._fail(fault)
                raise fault from error

    def _read_loop(self, ser: serial.Serial, halt: threading.Event) -> None:
        while not halt.is_set():
            try:
                data = ser.read(max(1, ser.in_waiting))
            except (serial.SerialException, OSError, TypeError, AttributeError) as error:
                if not halt.is_set():
                    self._fail(P2osError(f"serial port {self.port} failed: {error}"))
                return
            for payload in self.parser.feed(data):
                if payload[0] in (SipType.STOPPED, SipType.MOVING):
                    try:
                        raw = decode_standard_sip(payload)
                    except ValueError:
                        self.bad_sips += 1
                        continue
                    self._on_sip(raw, sip_to_si(raw, self.factors))

    def _pulse_loop(self, halt: threading.Event) -> None:
        while not halt.wait(self.settings.pulse_s):
            try:
                self._send(pulse_frame())
            except P2osError:
                return

    def _on_sip(self, raw: StandardSipRaw, sip: StandardSip) -> None:
        """Integrate the SIP's position into the odometry (REP-103, continuous); ``raw`` in the
        model's counts, ``sip`` the same in SI."""
        xc, yc = raw.x_counts, raw.y_counts
        m_per_count = self.factors.mm_per_count / 1000.0
        with self._cond:
            if self._fw_prev is None:  # a new connection: anchor the firmware frame here
                o = self._odom
                self._anchor = (o.x_m, o.y_m, o.heading_rad)
                self._fw_heading0 = sip.heading_rad
                self._fw_xy_m = (0.0, 0.0)
            else:
                px, py = self._fw_prev
                fx, fy = self._fw_xy_m
                self._fw_xy_m = (
                    fx + position_delta_counts(px, xc) * m_per_count,
                    fy + position_delta_counts(py, yc) * m_per_count,
                )
            self._fw_prev = (xc, yc)
            ax, ay, ah = self._anchor
            rot = ah - self._fw_heading0  # firmware frame -> odometry frame
            fx, fy = self._fw_xy_m
            heading = float(wrap_angle_rad(sip.heading_rad + rot))
            self._heading_total_rad += float(wrap_angle_rad(heading - self._odom.heading_rad))
            self._odom = Pose2D(
                ax + fx * math.cos(rot) - fy * math.sin(rot),
                ay + fx * math.sin(rot) + fy * math.cos(rot),
                heading,
            )
            self._sip = sip
            self._seq += 1
            self._cond.notify_all()

    def _next_sip(self, after: int, interruptible: bool = True) -> tuple[int, StandardSip]:
        """The first SIP after number ``after`` (or the latest one when a move is stopped, if
        ``interruptible``); raises on a fault or after ``sip_timeout_s`` without one."""
        timeout_s = self.settings.sip_timeout_s

        def ready() -> bool:
            stopped = interruptible and self._stop_move.is_set() and self._sip is not None
            return self._seq > after or self._fault is not None or stopped

        with self._cond:
            done = self._cond.wait_for(ready, timeout_s)
            if self._fault is not None:
                raise self._fault
            if not done or self._sip is None:
                raise P2osError(f"no SIP from {self.port} for {timeout_s:g} s")
            return self._seq, self._sip

    # -- the Robot protocol's base part -------------------------------------------------------

    def odometry(self) -> Pose2D:
        """The odometry pose from the latest SIP."""
        self.ensure_connected()
        with self._cond:
            return self._odom

    def latest_sip(self) -> StandardSip | None:
        """The latest SIP (SI units), or None before the first."""
        with self._cond:
            return self._sip

    def stop(self) -> None:
        """STOP now; a move in progress returns early. Best effort: if the port is gone the
        firmware's watchdog stops the robot."""
        self._stop_move.set()
        with self._cond:
            self._cond.notify_all()
        with contextlib.suppress(P2osError):
            self._send(stop_frame())

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        """Turn by ``turn_rad`` (wrapped to +-pi: the short way) then drive ``forward_m``."""
        if not (math.isfinite(turn_rad) and math.isfinite(forward_m)):
            raise ValueError(
                f"move needs finite turn_rad and forward_m, got {turn_rad}, {forward_m}"
            )
        self._stop_move.clear()  # before connecting: a stop() during a reconnect still counts
        self.ensure_connected()
        try:
            turned = self._turn(float(wrap_angle_rad(turn_rad)))
            if self._stop_move.is_set():
                return MoveResult(turned, 0.0, False)
            moved, bumped = self._drive_reacting(forward_m)
            return MoveResult(turned, moved, bumped)
        except P2osError:
            with contextlib.suppress(P2osError):
                self._send(stop_frame())
            raise

    def _turn(self, turn_rad: float) -> float:
        s = self.settings
        seq, _ = self._next_sip(self._seq)
        with self._cond:
            start = self._heading_total_rad
        if abs(turn_rad) < s.turn_tol_rad:
            return 0.0
        self._send(dhead_frame(round(math.degrees(turn_rad))))
        deadline = time.monotonic() + abs(turn_rad) / s.min_turn_rate_rad_s + s.settle_s
        while not self._stop_move.is_set():
            seq, sip = self._next_sip(seq)
            with self._cond:
                done = self._heading_total_rad - start
            turning = abs(sip.right_vel_m_s - sip.left_vel_m_s) > 0.005
            # the heading reached, not the path: a turn of +180 deg that the firmware took the
            # other way round (-180 deg) has arrived too
            if abs(float(wrap_angle_rad(turn_rad - done))) < s.turn_tol_rad and not turning:
                return done
            if time.monotonic() > deadline:
                self._send(stop_frame())
                raise P2osError(
                    f"{self.port}: a turn of {math.degrees(turn_rad):.0f} deg did not finish in "
                    f"time (turned {math.degrees(done):.0f} deg); the base was stopped"
                )
        with self._cond:
            return self._heading_total_rad - start

    def _drive_reacting(self, forward_m: float) -> tuple[float, bool]:
        """Drive, and on contact back off (thesis 5.3.2); net distance along the heading."""
        with self._cond:
            x0, y0, h = self._odom.x_m, self._odom.y_m, self._odom.heading_rad
        bumped = self._drive(forward_m, self.settings.max_speed_m_s)
        if bumped and not self._stop_move.is_set():
            back = -math.copysign(self.settings.backoff_m, forward_m)
            self._drive(back, self.settings.backoff_m_s)
        with self._cond:
            o = self._odom
        return (o.x_m - x0) * math.cos(h) + (o.y_m - y0) * math.sin(h), bumped

    def _drive(self, distance_m: float, max_speed_m_s: float) -> bool:
        """VEL until ``distance_m`` is driven along the heading, then STOP; whether a bumper or
        stall flag on the driving side ended it."""
        s = self.settings
        if abs(distance_m) < s.distance_tol_m:
            return False
        seq, _ = self._next_sip(self._seq)
        with self._cond:
            x0, y0, h = self._odom.x_m, self._odom.y_m, self._odom.heading_rad
        sign = 1.0 if distance_m > 0 else -1.0
        min_speed = min(s.min_speed_m_s, max_speed_m_s)
        deadline = time.monotonic() + abs(distance_m) / min_speed + s.settle_s
        sent: int | None = None
        contact = False
        while not self._stop_move.is_set():
            seq, sip = self._next_sip(seq)
            with self._cond:
                o = self._odom
            done = sign * ((o.x_m - x0) * math.cos(h) + (o.y_m - y0) * math.sin(h))
            bumpers = sip.front_bumpers if sign > 0 else sip.rear_bumpers
            if bumpers or sip.left_stall or sip.right_stall:
                contact = True
                break
            remaining = abs(distance_m) - done
            if remaining <= s.distance_tol_m:
                break
            speed = min(max(s.slowdown_per_s * remaining, min_speed), max_speed_m_s)
            mm_s = round(sign * speed * 1000.0)
            if mm_s != sent:
                self._send(vel_frame(mm_s))
                sent = mm_s
            if time.monotonic() > deadline:
                self._send(stop_frame())
                raise P2osError(
                    f"{self.port}: a drive of {distance_m:.2f} m did not finish in time "
                    f"({done:.2f} m driven); the base was stopped"
                )
        self._send(stop_frame())
        self._settle(seq)
        return contact

    def _settle(self, seq: int) -> None:
        """Wait (up to ``settle_s``) for a SIP saying the wheels stand still."""
        deadline = time.monotonic() + self.settings.settle_s
        while time.monotonic() < deadline:
            seq, sip = self._next_sip(seq)
            if not sip.moving or self._stop_move.is_set():
                return
