"""The Pioneer P2OS/ARCOS serial protocol as pure byte codecs: no I/O, no serial port.

Frame (client commands and robot server information packets alike)::

    0xFA 0xFB | count | payload (count - 2 bytes) | checksum high | checksum low

``count`` is the number of bytes after it: the payload plus the 2 checksum bytes. The payload's
first byte is the command number (client to robot) or the packet type (robot to client). The
checksum sums the payload's successive byte pairs as big-endian 16-bit integers, keeping the sum
to 16 bits; an odd last byte is XORed in; it is sent high byte first.

Matched against (reference only, nothing copied):

* framing and checksum: ARIA ``ArRobotPacket::finalizePacket`` / ``calcCheckSum`` /
  ``verifyCheckSum`` (MRPT's bundled ARIA, ``libs/hwdrivers/src/aria/src/ArRobotPacket.cpp``) and
  the ROS p2os driver ``P2OSPacket::Build`` / ``CalcChkSum`` (allenh1/p2os,
  ``p2os_driver/src/packet.cpp``, which refuses frames over 200 bytes);
* command numbers and argument types (0x3B positive int, 0x1B negative int, 0x2B string, then the
  2-byte little-endian magnitude): ARIA ``ArCommands.h`` and p2os ``robot_params.hpp``;
* the standard SIP's field order: p2os ``SIP::ParseStandard`` (``p2os_driver/src/sip.cpp``).
  p2os masks the position with ``0xEFFF`` and unwraps it modulo 4096; we keep the 15 low bits
  (``0x7FFF``, unwrapped modulo 32768) as the operations manual describes x and y.

Units: firmware units in the command builders (mm, mm/s, deg, deg/s) and the model's units in the
``*Raw`` SIP (:class:`ConversionFactors`; tenths of volts); SI in :class:`StandardSip` (m, rad,
m/s, V).
Frame: the robot's odometry frame as the firmware keeps it (x forward at power-on, y left, heading
counter-clockwise), REP-103 like the rest of toploc.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntEnum

from homing.bearings import wrap_angle_rad

HEADER = b"\xfa\xfb"
MAX_COUNT = 200
"""The largest byte count a frame may carry (payload + checksum); p2os refuses bigger frames."""
MIN_COUNT = 3
"""A payload holds at least its command number or packet type."""
MAX_PAYLOAD = MAX_COUNT - 2

SYNC0, SYNC1, SYNC2 = 0, 1, 2
"""The connection handshake: the client sends SYNC0, SYNC1, SYNC2 and the robot echoes each."""


class Command(IntEnum):
    """Client command numbers (ARIA ``ArCommands``, p2os ``P2OSCommand``)."""

    PULSE = 0  # no argument: keep-alive for the watchdog
    OPEN = 1  # no argument: start the servers after the sync
    CLOSE = 2  # no argument: close the connection
    ENABLE = 4  # int: 1 enables the motors, 0 disables them
    VEL = 11  # int: translational velocity, mm/s
    HEAD = 12  # int: turn to an absolute heading, degrees
    DHEAD = 13  # int: turn relative to the current heading, degrees
    RVEL = 21  # int: rotational velocity, deg/s
    STOP = 29  # no argument: stop the robot, motors stay enabled


class ArgType(IntEnum):
    """The byte that follows the command number and says how to read its argument."""

    INT = 0x3B  # positive (or zero) int: 2 bytes, little-endian magnitude
    NEG_INT = 0x1B  # negative int: 2 bytes, little-endian magnitude
    STRING = 0x2B  # string: 1 length byte, then the bytes


class SipType(IntEnum):
    """Standard server information packet types."""

    STOPPED = 0x32  # motors stopped
    MOVING = 0x33  # motors moving


# --- framing ---------------------------------------------------------------------------------


def checksum(payload: bytes) -> int:
    """The 16-bit frame checksum of ``payload`` (the bytes between the count and the checksum)."""
    c = 0
    n = len(payload)
    for i in range(0, n - 1, 2):
        c = (c + ((payload[i] << 8) | payload[i + 1])) & 0xFFFF
    if n % 2:
        c ^= payload[-1]
    return c


def encode_frame(payload: bytes) -> bytes:
    """The full frame for ``payload``: header, count, payload, checksum (high byte first)."""
    if not 1 <= len(payload) <= MAX_PAYLOAD:
        raise ValueError(f"a payload has 1 to {MAX_PAYLOAD} bytes, got {len(payload)}")
    c = checksum(payload)
    return HEADER + bytes([len(payload) + 2]) + payload + bytes([c >> 8, c & 0xFF])


def decode_frame(frame: bytes) -> bytes:
    """The payload of one complete ``frame``; ``ValueError`` saying what is wrong otherwise."""
    if frame[:2] != HEADER:
        raise ValueError(f"a frame starts with FA FB, got {frame[:2].hex(' ').upper()!r}")
    if len(frame) < 3 or not MIN_COUNT <= frame[2] <= MAX_COUNT:
        got = frame[2] if len(frame) > 2 else "nothing"
        raise ValueError(f"a frame's byte count is {MIN_COUNT} to {MAX_COUNT}, got {got}")
    if len(frame) != frame[2] + 3:
        raise ValueError(
            f"byte count {frame[2]} needs a {frame[2] + 3}-byte frame, got {len(frame)}"
        )
    payload = frame[3:-2]
    sent = (frame[-2] << 8) | frame[-1]
    if sent != checksum(payload):
        raise ValueError(f"checksum {sent:#06x} sent, {checksum(payload):#06x} computed")
    return payload


# --- commands --------------------------------------------------------------------------------


def int_arg(value: int) -> bytes:
    """The argument bytes of a signed 16-bit int: type byte by sign, then the magnitude (LE)."""
    if not -32768 <= value <= 32767:
        raise ValueError(f"an int argument is a signed 16-bit integer, got {value}")
    kind = ArgType.INT if value >= 0 else ArgType.NEG_INT
    return bytes([kind]) + abs(value).to_bytes(2, "little")


def string_arg(text: bytes) -> bytes:
    """The argument bytes of a string: type byte, length byte, the bytes."""
    if len(text) > MAX_PAYLOAD - 3:
        raise ValueError(f"a string argument has at most {MAX_PAYLOAD - 3} bytes, got {len(text)}")
    return bytes([ArgType.STRING, len(text)]) + text


def command_frame(command: int, arg: int | bytes | None = None) -> bytes:
    """The frame of ``command`` (0-255) with no argument, an int argument or a string argument."""
    if not 0 <= command <= 255:
        raise ValueError(f"a command number is 0-255, got {command}")
    if arg is None:
        tail = b""
    elif isinstance(arg, bytes):
        tail = string_arg(arg)
    else:
        tail = int_arg(arg)
    return encode_frame(bytes([command]) + tail)


@dataclass(frozen=True)
class CommandPacket:
    """A decoded client command: its number and argument (``None``, an int, or string bytes)."""

    command: int
    arg: int | bytes | None = None


def parse_command(payload: bytes) -> CommandPacket:
    """The command in a frame's ``payload`` (the inverse of :func:`command_frame`'s payload)."""
    if not payload:
        raise ValueError("a command payload holds at least the command number, got 0 bytes")
    command, rest = payload[0], payload[1:]
    if not rest:
        return CommandPacket(command)
    kind = rest[0]
    if kind in (ArgType.INT, ArgType.NEG_INT):
        if len(rest) != 3:
            raise ValueError(f"an int argument has 2 bytes, got {len(rest) - 1}")
        magnitude = int.from_bytes(rest[1:3], "little")
        return CommandPacket(command, magnitude if kind == ArgType.INT else -magnitude)
    if kind == ArgType.STRING:
        if len(rest) < 2 or len(rest) != rest[1] + 2:
            raise ValueError(f"a string argument's length byte must match, got {rest[1:].hex()}")
        return CommandPacket(command, bytes(rest[2:]))
    raise ValueError(f"argument type is 0x3B, 0x1B or 0x2B, got {kind:#04x}")


def sync_frame(n: int) -> bytes:
    """SYNC0, SYNC1 or SYNC2 (``n`` = 0, 1, 2): the handshake frames; SYNC0 is FA FB 03 00 00 00."""
    if n not in (SYNC0, SYNC1, SYNC2):
        raise ValueError(f"sync frames are 0, 1, 2, got {n}")
    return command_frame(n)


def open_frame() -> bytes:
    """OPEN: start the robot's servers after the sync."""
    return command_frame(Command.OPEN)


def close_frame() -> bytes:
    """CLOSE: end the connection."""
    return command_frame(Command.CLOSE)


def pulse_frame() -> bytes:
    """PULSE: keep the watchdog from stopping the robot."""
    return command_frame(Command.PULSE)


def enable_frame(enabled: bool) -> bytes:
    """ENABLE 1 or 0: motors on or off."""
    return command_frame(Command.ENABLE, 1 if enabled else 0)


def stop_frame() -> bytes:
    """STOP: stop translation and rotation (motors stay enabled)."""
    return command_frame(Command.STOP)


def vel_frame(speed_mm_s: int) -> bytes:
    """VEL: translational velocity in mm/s, positive forward."""
    return command_frame(Command.VEL, speed_mm_s)


def rvel_frame(rate_deg_s: int) -> bytes:
    """RVEL: rotational velocity in deg/s, positive counter-clockwise."""
    return command_frame(Command.RVEL, rate_deg_s)


def head_frame(heading_deg: int) -> bytes:
    """HEAD: turn to an absolute odometry heading, degrees (taken modulo 360 into 0-359)."""
    return command_frame(Command.HEAD, heading_deg % 360)


def dhead_frame(turn_deg: int) -> bytes:
    """DHEAD: turn by ``turn_deg`` degrees from the current heading, positive counter-clockwise."""
    return command_frame(Command.DHEAD, turn_deg)


def velocity_frames(linear_m_s: float, angular_rad_s: float) -> tuple[bytes, bytes]:
    """VEL and RVEL frames for an SI twist, rounded to whole mm/s and deg/s."""
    if not (math.isfinite(linear_m_s) and math.isfinite(angular_rad_s)):
        raise ValueError(f"velocities must be finite, got {linear_m_s}, {angular_rad_s}")
    return vel_frame(round(linear_m_s * 1000.0)), rvel_frame(round(math.degrees(angular_rad_s)))


# --- the streaming parser --------------------------------------------------------------------


class FrameParser:
    """Complete frames out of a byte stream fed in arbitrary chunks; never raises.

    Bytes before a header are skipped. A header whose count is out of range, or a frame whose
    checksum fails, costs only its first byte: the search for the next header resumes one byte
    later, so a false header in noise cannot swallow a real frame that starts inside it. A
    header whose frame has not fully arrived waits for more bytes (the stream cannot tell a
    truncated frame from a slow one); the next frames bring its bytes and its checksum fails.

    Every byte fed is in exactly one of: a returned payload's frame, ``skipped_bytes``,
    ``pending`` (kept for the next chunk).
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.frames = 0
        self.skipped_bytes = 0
        self.bad_checksums = 0
        self.bad_counts = 0

    @property
    def pending(self) -> int:
        """Bytes held back: an incomplete frame, or a trailing 0xFA that may start a header."""
        return len(self._buf)

    def feed(self, chunk: bytes) -> list[bytes]:
        """The payloads of the frames that ``chunk`` completes, in stream order."""
        buf = self._buf
        buf += chunk
        out: list[bytes] = []
        i = 0
        while True:
            j = buf.find(HEADER, i)
            if j < 0:
                keep = len(buf) - 1 if len(buf) > i and buf[-1] == HEADER[0] else len(buf)
                self.skipped_bytes += keep - i
                i = keep
                break
            self.skipped_bytes += j - i
            i = j
            if len(buf) < i + 3:
                break
            count = buf[i + 2]
            if not MIN_COUNT <= count <= MAX_COUNT:
                self.bad_counts += 1
                self.skipped_bytes += 1
                i += 1
                continue
            end = i + 3 + count
            if len(buf) < end:
                break
            payload = bytes(buf[i + 3 : end - 2])
            if checksum(payload) == (buf[end - 2] << 8) | buf[end - 1]:
                out.append(payload)
                self.frames += 1
                i = end
            else:
                self.bad_checksums += 1
                self.skipped_bytes += 1
                i += 1
        del buf[:i]
        return out


# --- standard server information packets -----------------------------------------------------

_SIP_FIXED = struct.Struct("<BHHhhhBBBhHBB")
"""type, x, y, heading, left vel, right vel, battery, stall+rear bumpers, stall+front bumpers,
control, flags, compass, sonar count: the standard SIP up to its sonar readings (20 bytes)."""
_SONAR = struct.Struct("<BH")
POSITION_WRAP = 1 << 15
"""The firmware's x and y are the 15 low bits of its integrated encoder position."""


@dataclass(frozen=True)
class StandardSipRaw:
    """A standard SIP in firmware units, fields in the order the robot sends them.

    The units are the model's (:class:`ConversionFactors`, chosen per model by
    :mod:`robot.p2os_models`). ``x_counts``/``y_counts`` wrap at 2**15 (see
    :func:`position_delta_counts`); a count is 1 mm on a Pioneer 3 with the SH controller, 0.485
    mm on a classic P3-DX (``DistConvFactor``). ``heading_units``: 4096 per revolution on a
    Pioneer 2 or 3 (1024 on a Pioneer 1), counter-clockwise. Wheel velocities in velocity units
    (1 mm/s on a Pioneer 3, ``VelConvFactor``), battery in tenths of volts. Bumper bits: bit 0 is
    the first bumper; ``flags`` bit 0 is "motors enabled". Sonar readings are ``(sonar index,
    range in range units)`` pairs, only the sonars fired this cycle.
    Bytes after the sonar readings (timer, analog, digital I/O...) vary with the firmware and are
    not decoded.
    """

    moving: bool
    x_counts: int
    y_counts: int
    heading_units: int
    left_vel_units: int
    right_vel_units: int
    battery_decivolts: int
    left_stall: bool
    right_stall: bool
    rear_bumpers: int
    front_bumpers: int
    control: int = 0
    flags: int = 0
    compass: int = 0
    sonars: tuple[tuple[int, int], ...] = ()

    @property
    def motors_enabled(self) -> bool:
        """Bit 0 of ``flags``."""
        return bool(self.flags & 1)


def decode_standard_sip(payload: bytes) -> StandardSipRaw:
    """The standard SIP in a frame's ``payload`` (type 0x32 or 0x33 first)."""
    if len(payload) < _SIP_FIXED.size:
        raise ValueError(f"a standard SIP has at least {_SIP_FIXED.size} bytes, got {len(payload)}")
    kind, x, y, th, lv, rv, batt, lo, hi, control, flags, compass, n = _SIP_FIXED.unpack_from(
        payload
    )
    if kind not in (SipType.STOPPED, SipType.MOVING):
        raise ValueError(f"a standard SIP's type is 0x32 or 0x33, got {kind:#04x}")
    end = _SIP_FIXED.size + n * _SONAR.size
    if len(payload) < end:
        raise ValueError(f"{n} sonar readings need {end} bytes, got {len(payload)}")
    sonars = tuple(_SONAR.unpack_from(payload, _SIP_FIXED.size + k * _SONAR.size) for k in range(n))
    return StandardSipRaw(
        moving=kind == SipType.MOVING,
        x_counts=x & (POSITION_WRAP - 1),
        y_counts=y & (POSITION_WRAP - 1),
        heading_units=th,
        left_vel_units=lv,
        right_vel_units=rv,
        battery_decivolts=batt,
        left_stall=bool(lo & 1),
        right_stall=bool(hi & 1),
        rear_bumpers=lo >> 1,
        front_bumpers=hi >> 1,
        control=control,
        flags=flags,
        compass=compass,
        sonars=sonars,
    )


def encode_standard_sip(sip: StandardSipRaw) -> bytes:
    """The payload of ``sip`` (the robot's side; for simulators and tests)."""
    kind = SipType.MOVING if sip.moving else SipType.STOPPED
    fixed = _SIP_FIXED.pack(
        kind,
        sip.x_counts,
        sip.y_counts,
        sip.heading_units,
        sip.left_vel_units,
        sip.right_vel_units,
        sip.battery_decivolts,
        (sip.rear_bumpers << 1) | sip.left_stall,
        (sip.front_bumpers << 1) | sip.right_stall,
        sip.control,
        sip.flags,
        sip.compass,
        len(sip.sonars),
    )
    return fixed + b"".join(_SONAR.pack(i, r) for i, r in sip.sonars)


def position_delta_counts(previous: int, current: int) -> int:
    """The signed change between two 15-bit wrapped positions, the shorter way round."""
    d = (current - previous) % POSITION_WRAP
    return d - POSITION_WRAP if d >= POSITION_WRAP // 2 else d


@dataclass(frozen=True)
class ConversionFactors:
    """A SIP's firmware units to SI; the defaults are a Pioneer 3-SH's (p2os/ARIA robot
    parameters; :data:`robot.p2os_models.MODEL_FACTORS` has every model's)."""

    mm_per_count: float = 1.0  # DistConvFactor
    rad_per_angle_unit: float = 0.001534  # AngleConvFactor (2 pi / 4096, as ARIA rounds it)
    mm_s_per_vel_unit: float = 1.0  # VelConvFactor
    mm_per_range_unit: float = 1.0  # RangeConvFactor

    @property
    def angle_units_per_rev(self) -> int:
        """Heading units in one revolution (4096 on a Pioneer 2 or 3, 1024 on a Pioneer 1)."""
        return round(2.0 * math.pi / self.rad_per_angle_unit)


@dataclass(frozen=True)
class StandardSip:
    """A standard SIP in SI units, in the firmware's odometry frame (REP-103).

    ``x_m``/``y_m`` are the *wrapped* positions (they jump by 32.768 m at the wrap); integrate
    :func:`position_delta_counts` for odometry. ``heading_rad`` in (-pi, pi].
    """

    moving: bool
    x_m: float
    y_m: float
    heading_rad: float
    left_vel_m_s: float
    right_vel_m_s: float
    battery_v: float
    left_stall: bool
    right_stall: bool
    rear_bumpers: int
    front_bumpers: int
    motors_enabled: bool
    sonar_ranges_m: tuple[tuple[int, float], ...] = ()

    @property
    def linear_m_s(self) -> float:
        """Forward speed: the mean of the wheel speeds."""
        return (self.left_vel_m_s + self.right_vel_m_s) / 2.0


def sip_to_si(raw: StandardSipRaw, factors: ConversionFactors | None = None) -> StandardSip:
    """``raw`` converted to SI with ``factors`` (a Pioneer 3-SH's by default). The heading is
    its units' share of a revolution (:attr:`ConversionFactors.angle_units_per_rev`), so the
    factor's rounding does not drift it past +-pi."""
    f = factors or ConversionFactors()
    return StandardSip(
        moving=raw.moving,
        x_m=raw.x_counts * f.mm_per_count / 1000.0,
        y_m=raw.y_counts * f.mm_per_count / 1000.0,
        heading_rad=float(
            wrap_angle_rad(2.0 * math.pi * raw.heading_units / f.angle_units_per_rev)
        ),
        left_vel_m_s=raw.left_vel_units * f.mm_s_per_vel_unit / 1000.0,
        right_vel_m_s=raw.right_vel_units * f.mm_s_per_vel_unit / 1000.0,
        battery_v=raw.battery_decivolts / 10.0,
        left_stall=raw.left_stall,
        right_stall=raw.right_stall,
        rear_bumpers=raw.rear_bumpers,
        front_bumpers=raw.front_bumpers,
        motors_enabled=raw.motors_enabled,
        sonar_ranges_m=tuple((i, r * f.mm_per_range_unit / 1000.0) for i, r in raw.sonars),
    )
