"""The P2OS/ARCOS codec: frames, checksums, commands, the streaming parser, standard SIPs."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robot.p2os_protocol import (
    HEADER,
    MAX_PAYLOAD,
    Command,
    CommandPacket,
    FrameParser,
    StandardSipRaw,
    checksum,
    close_frame,
    command_frame,
    decode_frame,
    decode_standard_sip,
    dhead_frame,
    enable_frame,
    encode_frame,
    encode_standard_sip,
    head_frame,
    open_frame,
    parse_command,
    position_delta_counts,
    pulse_frame,
    rvel_frame,
    sip_to_si,
    stop_frame,
    sync_frame,
    vel_frame,
    velocity_frames,
)

payloads = st.binary(min_size=1, max_size=MAX_PAYLOAD)


def naive_checksum(payload: bytes) -> int:
    """The manual's wording, slowly: big-endian pairs summed mod 2**16, odd last byte XORed."""
    words = [int.from_bytes(payload[i : i + 2], "big") for i in range(0, len(payload) - 1, 2)]
    c = sum(words) % 65536
    return c ^ payload[-1] if len(payload) % 2 else c


# --- known bytes -----------------------------------------------------------------------------


def test_sync_frames_are_the_manuals_bytes():
    assert sync_frame(0) == bytes.fromhex("FA FB 03 00 00 00")
    assert sync_frame(1) == bytes.fromhex("FA FB 03 01 00 01")
    assert sync_frame(2) == bytes.fromhex("FA FB 03 02 00 02")


def test_command_frames_known_bytes():
    assert pulse_frame() == bytes.fromhex("FA FB 03 00 00 00")
    assert open_frame() == bytes.fromhex("FA FB 03 01 00 01")
    assert close_frame() == bytes.fromhex("FA FB 03 02 00 02")
    assert stop_frame() == bytes.fromhex("FA FB 03 1D 00 1D")
    # ENABLE 1: payload 04 3B 01 00 -> 0x043B + 0x0100 = 0x053B
    assert enable_frame(True) == bytes.fromhex("FA FB 06 04 3B 01 00 05 3B")
    assert enable_frame(False) == bytes.fromhex("FA FB 06 04 3B 00 00 04 3B")
    # VEL 300 mm/s: 0B 3B 2C 01 -> 0x0B3B + 0x2C01 = 0x373C
    assert vel_frame(300) == bytes.fromhex("FA FB 06 0B 3B 2C 01 37 3C")
    # VEL -100 mm/s: negative-int type 0x1B, magnitude 100 little-endian
    assert vel_frame(-100) == bytes.fromhex("FA FB 06 0B 1B 64 00 6F 1B")
    assert rvel_frame(-10)[3:7] == bytes.fromhex("15 1B 0A 00")
    assert head_frame(-90)[3:7] == bytes.fromhex("0C 3B 0E 01")  # 270 degrees
    assert dhead_frame(45)[3:7] == bytes.fromhex("0D 3B 2D 00")


def test_checksum_known_values():
    assert checksum(b"\x00") == 0x0000
    assert checksum(b"\x04\x3b\x01\x00") == 0x053B
    assert checksum(b"\x01\x02\x03") == 0x0102 ^ 0x03  # odd last byte is XORed
    assert checksum(b"\xff\xff\x00\x02") == 0x0001  # the sum is kept to 16 bits


@given(payloads)
@settings(max_examples=200)
def test_checksum_matches_the_naive_definition(payload):
    assert checksum(payload) == naive_checksum(payload)


def test_command_numbers_match_arcommands():
    assert {c.name: int(c) for c in Command} == {
        "PULSE": 0,
        "OPEN": 1,
        "CLOSE": 2,
        "ENABLE": 4,
        "VEL": 11,
        "HEAD": 12,
        "DHEAD": 13,
        "RVEL": 21,
        "STOP": 29,
    }


# --- round trips and refusals ----------------------------------------------------------------


@given(payloads)
@settings(max_examples=200)
def test_frame_round_trip(payload):
    frame = encode_frame(payload)
    assert frame[:2] == HEADER and frame[2] == len(payload) + 2 and len(frame) == len(payload) + 5
    assert decode_frame(frame) == payload


@given(
    st.integers(0, 255),
    st.one_of(st.none(), st.integers(-32768, 32767), st.binary(max_size=MAX_PAYLOAD - 3)),
)
@settings(max_examples=200)
def test_command_round_trip(command, arg):
    assert parse_command(decode_frame(command_frame(command, arg))) == CommandPacket(command, arg)


def test_refusals_say_what_they_got():
    with pytest.raises(ValueError, match="got 0"):
        encode_frame(b"")
    with pytest.raises(ValueError, match="got 199"):
        encode_frame(bytes(199))
    with pytest.raises(ValueError, match="got 32768"):
        vel_frame(32768)
    with pytest.raises(ValueError, match="got 3"):
        sync_frame(3)
    with pytest.raises(ValueError, match="checksum"):
        decode_frame(bytes.fromhex("FA FB 03 00 00 01"))
    with pytest.raises(ValueError, match="FA FB"):
        decode_frame(bytes.fromhex("FA FC 03 00 00 00"))
    with pytest.raises(ValueError, match="argument type"):
        parse_command(bytes.fromhex("0B 4B 01 00"))
    with pytest.raises(ValueError, match="finite"):
        velocity_frames(math.nan, 0.0)


def test_velocity_frames_in_si():
    vel, rvel = velocity_frames(0.25, math.radians(-30.0))
    assert parse_command(decode_frame(vel)) == CommandPacket(Command.VEL, 250)
    assert parse_command(decode_frame(rvel)) == CommandPacket(Command.RVEL, -30)


# --- the streaming parser --------------------------------------------------------------------


def feed_in_chunks(parser: FrameParser, stream: bytes, cuts: list[int]) -> list[bytes]:
    out: list[bytes] = []
    bounds = [0, *sorted(c % (len(stream) + 1) for c in cuts), len(stream)]
    for a, b in itertools.pairwise(bounds):
        out += parser.feed(stream[a:b])
    return out


def test_parser_skips_garbage_and_resyncs_after_a_bad_checksum():
    good = vel_frame(300)
    bad = bytearray(enable_frame(True))
    bad[-1] ^= 0xFF
    parser = FrameParser()
    out = parser.feed(b"\x01\x02" + bytes(bad) + good[:4])
    assert out == []
    out = parser.feed(good[4:] + stop_frame())
    assert out == [decode_frame(good), decode_frame(stop_frame())]
    assert parser.bad_checksums == 1
    assert parser.skipped_bytes == 2 + len(bad)
    assert parser.pending == 0


def test_parser_finds_a_frame_inside_a_truncated_one():
    # A frame cut after its count byte: its claimed length swallows the next frame, the checksum
    # fails, and the search resumes one byte after the false header.
    truncated = vel_frame(300)[:4]
    good = [enable_frame(True), stop_frame(), vel_frame(-5)]
    parser = FrameParser()
    out = parser.feed(truncated + b"".join(good))
    assert out == [decode_frame(f) for f in good]
    assert parser.bad_checksums == 1 and parser.skipped_bytes == len(truncated)


def test_parser_rejects_out_of_range_counts():
    parser = FrameParser()
    assert parser.feed(b"\xfa\xfb\x02" + pulse_frame() + b"\xfa\xfb\xc9") == [b"\x00"]
    assert parser.bad_counts == 2


@given(st.binary(max_size=600), st.lists(st.integers(0, 600), max_size=8))
@settings(max_examples=300)
def test_random_bytes_never_raise_and_every_byte_is_accounted_for(stream, cuts):
    parser = FrameParser()
    out = feed_in_chunks(parser, stream, cuts)
    in_frames = sum(len(p) + 5 for p in out)
    assert in_frames + parser.skipped_bytes + parser.pending == len(stream)
    assert parser.frames == len(out)
    for payload in out:  # whatever it returns is a real frame of the stream
        assert encode_frame(payload) in stream


headerless = st.binary(max_size=40).filter(lambda g: HEADER not in g)


@given(
    st.lists(st.tuples(headerless, payloads.filter(lambda p: len(p) <= 30)), max_size=6),
    headerless,
    st.lists(st.integers(0, 2000), max_size=8),
)
@settings(max_examples=300)
def test_frames_between_headerless_garbage_are_all_recovered(pieces, tail, cuts):
    # Garbage with no FA FB in it cannot start a false frame. It cannot make one with a real
    # frame either: a header needs FB after FA, and a frame starts with FA FB, so garbage ending
    # in FA before it reads FA FA FB; and a frame is consumed whole before the bytes after it
    # are searched. So every frame comes out, in order, and only garbage is skipped. (With
    # headers in the garbage a false frame could pass its checksum by chance: 1 in 65536.)
    stream = b"".join(g + encode_frame(p) for g, p in pieces) + tail
    parser = FrameParser()
    out = feed_in_chunks(parser, stream, cuts)
    assert out == [p for _, p in pieces]
    assert parser.bad_checksums == 0
    garbage = sum(len(g) for g, _ in pieces) + len(tail)
    assert parser.skipped_bytes + parser.pending == garbage
    assert parser.pending <= 1  # at most a trailing FA that may start a header


# --- standard SIPs ---------------------------------------------------------------------------


def hand_built_sip() -> bytes:
    return bytes.fromhex(
        "33"  # moving
        "E8 03"  # x 1000 mm
        "30 F8"  # y 0xF830 -> 15 bits 0x7830 = 30768 mm
        "00 04"  # heading 1024 units = 90 degrees
        "2C 01"  # left 300 mm/s
        "D4 FE"  # right -300 mm/s
        "7D"  # battery 12.5 V
        "05"  # left stall, rear bumper bit 1
        "02"  # no right stall, front bumper bit 0
        "00 00"  # control
        "01 00"  # flags: motors enabled
        "00"  # compass
        "02"  # two sonar readings
        "03 DC 05"  # sonar 3 at 1500 mm
        "07 10 27"  # sonar 7 at 10000 mm
        "00 00 80 00 00"  # timer, analog, digin, digout: not decoded
    )


def test_standard_sip_decodes_a_hand_built_packet():
    raw = decode_standard_sip(hand_built_sip())
    assert raw == StandardSipRaw(
        moving=True,
        x_counts=1000,
        y_counts=0x7830,
        heading_units=1024,
        left_vel_units=300,
        right_vel_units=-300,
        battery_decivolts=125,
        left_stall=True,
        right_stall=False,
        rear_bumpers=0b10,
        front_bumpers=0b01,
        control=0,
        flags=1,
        compass=0,
        sonars=((3, 1500), (7, 10000)),
    )
    si = sip_to_si(raw)
    assert si.x_m == pytest.approx(1.0) and si.y_m == pytest.approx(30.768)
    assert si.heading_rad == pytest.approx(math.pi / 2)
    assert (si.left_vel_m_s, si.right_vel_m_s, si.linear_m_s) == pytest.approx((0.3, -0.3, 0.0))
    assert si.battery_v == pytest.approx(12.5)
    assert si.motors_enabled and si.sonar_ranges_m == ((3, 1.5), (7, 10.0))


def test_sip_heading_wraps_to_half_open_pi():
    raw = decode_standard_sip(hand_built_sip())
    for units, expected in [(2048, math.pi), (3072, -math.pi / 2), (-1024, -math.pi / 2)]:
        heading = sip_to_si(StandardSipRaw(**{**raw.__dict__, "heading_units": units})).heading_rad
        assert heading == pytest.approx(expected)


def test_sip_refusals():
    with pytest.raises(ValueError, match="0x32 or 0x33"):
        decode_standard_sip(b"\x90" + hand_built_sip()[1:])
    with pytest.raises(ValueError, match="2 sonar readings need"):
        decode_standard_sip(hand_built_sip()[:22])
    with pytest.raises(ValueError, match="at least 20"):
        decode_standard_sip(b"\x32")


sips = st.builds(
    StandardSipRaw,
    moving=st.booleans(),
    x_counts=st.integers(0, 32767),
    y_counts=st.integers(0, 32767),
    heading_units=st.integers(-32768, 32767),
    left_vel_units=st.integers(-32768, 32767),
    right_vel_units=st.integers(-32768, 32767),
    battery_decivolts=st.integers(0, 255),
    left_stall=st.booleans(),
    right_stall=st.booleans(),
    rear_bumpers=st.integers(0, 127),
    front_bumpers=st.integers(0, 127),
    control=st.integers(-32768, 32767),
    flags=st.integers(0, 65535),
    compass=st.integers(0, 255),
    sonars=st.lists(st.tuples(st.integers(0, 255), st.integers(0, 65535)), max_size=16).map(tuple),
)


@given(sips)
@settings(max_examples=200)
def test_sip_round_trip_through_a_frame_and_the_parser(raw):
    frame = encode_frame(encode_standard_sip(raw))
    (payload,) = FrameParser().feed(frame)
    assert decode_standard_sip(payload) == raw


@given(st.integers(0, 32767), st.integers(-16384, 16383))
def test_position_delta_undoes_the_15_bit_wrap(start, delta):
    assert position_delta_counts(start, (start + delta) % 32768) == delta
