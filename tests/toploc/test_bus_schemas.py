"""Every message declared once (toploc/bus/schemas.py): what a schema writes and reads, and that
no node or client declares a message of its own beside it."""

import ast
from pathlib import Path

import pytest

from toploc import bus
from toploc.bus import schemas

REPO = Path(__file__).resolve().parents[2]
CODEC_CALLS = {"encode", "decode", "check_fields", "request_json"}


def test_a_schema_writes_the_envelope_then_its_fields():
    data = schemas.ODOM.encode({"x_m": 1.5, "y_m": -2.0, "heading_deg": 90.0, "stamp": 7.0})
    assert data == (
        b'{"schema": 1, "kind": "odom", "x_m": 1.5, "y_m": -2.0, "heading_deg": 90.0, "stamp": 7.0}'
    )


def test_a_schema_reads_back_what_it_wrote():
    data = schemas.CMD.encode({"turn_deg": 90, "forward_m": 0.5})
    assert schemas.CMD.decode("toploc/r1/base/cmd", data) == {
        "schema": 1,
        "kind": "cmd",
        "turn_deg": 90,
        "forward_m": 0.5,
    }


def test_a_schema_refuses_a_message_without_one_of_its_fields():
    data = bus.encode("cmd", {"turn_deg": 90})
    with pytest.raises(bus.BusMessageError, match="base/cmd: missing field 'forward_m'"):
        schemas.CMD.decode("toploc/r1/base/cmd", data)


def test_a_schema_refuses_another_kind_unless_told_not_to_check_it():
    data = bus.encode("q", {"room": "office_a"})
    with pytest.raises(bus.BusMessageError, match="message kind 'q', expected 'places'"):
        schemas.PLACES_QUERY.decode("toploc/r1/map/places", data)
    assert schemas.PLACES_QUERY.decode("toploc/r1/map/places", data, check_kind=False)["room"]


def test_an_optional_field_is_checked_only_when_present():
    schemas.ADD.check_optional("toploc/r1/map/add", {"room": "a"})
    with pytest.raises(bus.BusMessageError, match="field 'x_m' must be float or null"):
        schemas.ADD.check_optional("toploc/r1/map/add", {"room": "a", "x_m": "1"})


def inline_messages(path: Path) -> list[str]:
    """Each ``bus.encode/decode/check_fields/request_json`` call in ``path`` given a kind as a
    string literal or fields as a dict display (a message declared beside schemas.py)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if not (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and isinstance(node.func.value, ast.Name)
            and node.func.value.id == "bus"
            and node.func.attr in CODEC_CALLS
        ):
            continue
        arguments = [*node.args, *(keyword.value for keyword in node.keywords)]
        literal = [a for a in arguments if isinstance(a, ast.Dict | ast.Constant)]
        if any(isinstance(a, ast.Dict) or isinstance(a.value, str) for a in literal):
            found.append(f"{path.relative_to(REPO)}:{node.lineno} bus.{node.func.attr}")
    return found


def test_no_node_or_client_declares_a_message_of_its_own():
    paths = sorted(
        [*(REPO / "toploc" / "nodes").glob("*.py"), *(REPO / "toploc/bus/clients").glob("*.py")]
    )
    assert [line for path in paths for line in inline_messages(path)] == []


def test_the_check_sees_a_message_declared_inline():
    probe = REPO / "toploc" / "nodes" / "_schema_probe.py"
    try:
        probe.write_text('from toploc import bus\n\nbus.encode("odom", {"x_m": 1.0})\n')
        assert inline_messages(probe) == ["toploc/nodes/_schema_probe.py:3 bus.encode"]
    finally:
        probe.unlink()
