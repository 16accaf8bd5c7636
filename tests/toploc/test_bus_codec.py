"""The bus contract without a network: key expressions, configuration and the JSON codec."""

import json

import pytest

from toploc import bus

KEY = "toploc/r1/localizer/belief"
FIELDS = {"rooms": dict, "entropy_bits": float, "state": str, "best_place": (dict, type(None))}


def test_keys_live_under_the_robot_id():
    assert bus.key("r1", bus.LOCALIZER_BELIEF) == KEY
    assert bus.alive_key("r1", "robot") == "toploc/r1/alive/robot"


@pytest.mark.parametrize("robot_id", ["", "a/b", "r*", "r$", "r?", "r#", " r"])
def test_a_robot_id_that_is_not_one_key_chunk_is_refused(robot_id):
    with pytest.raises(ValueError, match="robot id"):
        bus.key(robot_id, bus.BASE_CMD)


def test_config_defaults_to_a_local_peer_without_multicast():
    config = bus.BusConfig().to_zenoh()
    assert json.loads(config.get_json("mode")) == "peer"
    assert json.loads(config.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7447"]
    assert json.loads(config.get_json("connect/endpoints")) == []
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False


def test_config_takes_any_endpoint_and_mode():
    cfg = bus.BusConfig("r2", "client", listen=(), connect=["tcp/10.0.0.2:7448"])
    config = cfg.to_zenoh()
    assert json.loads(config.get_json("mode")) == "client"
    assert json.loads(config.get_json("connect/endpoints")) == ["tcp/10.0.0.2:7448"]
    assert cfg.connect == ("tcp/10.0.0.2:7448",)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"mode": "server"}, "mode must be one of"),
        ({"listen": "tcp/127.0.0.1:7447"}, "not the string"),
        ({"connect": ("127.0.0.1:7447",)}, "'127.0.0.1:7447' is not an endpoint"),
        ({"mode": "client", "connect": ()}, "client mode needs"),
    ],
)
def test_a_bad_config_names_the_problem(kwargs, match):
    with pytest.raises(ValueError, match=match):
        bus.BusConfig(**kwargs)


def test_encode_decode_round_trip():
    payload = {"rooms": {"a": 0.25, "b": 0.75}, "entropy_bits": 1, "state": "x", "best_place": None}
    data = bus.encode("belief", payload)
    message = bus.decode(KEY, data, FIELDS, kind="belief")
    assert message == {"schema": bus.SCHEMA_VERSION, "kind": "belief", **payload}


def test_encode_refuses_reserved_fields_and_nan():
    with pytest.raises(ValueError, match="reserved"):
        bus.encode("belief", {"schema": 2})
    with pytest.raises(ValueError, match="cannot be encoded"):
        bus.encode("belief", {"entropy_bits": float("nan")})


GOOD = {"schema": 1, "kind": "belief", "rooms": {}, "entropy_bits": 0.5, "state": "lost"}


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (b"", "empty payload"),
        (None, "empty payload"),
        (b"\x89PNG\r\n", "not JSON"),
        (b"{'schema': 1}", "not JSON"),
        (b"[1, 2]", "must be a JSON object, got list"),
        (b'"text"', "must be a JSON object, got str"),
        (json.dumps({**GOOD, "schema": 2}).encode(), "schema version 2, this toploc speaks 1"),
        (json.dumps({**GOOD, "schema": True}).encode(), "schema version True"),
        (json.dumps({k: v for k, v in GOOD.items() if k != "schema"}).encode(), "schema version"),
        (json.dumps({**GOOD, "kind": "odom"}).encode(), "kind 'odom', expected 'belief'"),
        (json.dumps({**GOOD, "best_place": None} | {"rooms": []}).encode(), "'rooms' must be dict"),
        (json.dumps(GOOD).encode(), "missing field 'best_place' \\(dict or null\\)"),
        (json.dumps({**GOOD, "best_place": 3}).encode(), "'best_place' must be dict or null"),
        (json.dumps({**GOOD, "best_place": None, "entropy_bits": "1"}).encode(), "entropy_bits"),
        (json.dumps({**GOOD, "best_place": None, "entropy_bits": True}).encode(), "entropy_bits"),
        (
            b'{"schema":1,"kind":"belief","rooms":{},"state":"lost","best_place":null,'
            b'"entropy_bits":NaN}',
            "'entropy_bits' must be float, got nan",
        ),
    ],
)
def test_decode_names_the_key_and_what_is_wrong(data, match):
    with pytest.raises(bus.BusMessageError, match=match) as caught:
        bus.decode(KEY, data, FIELDS, kind="belief")
    assert str(caught.value).startswith(KEY)


def test_field_types_follow_json():
    assert bus.has_type(3, float)
    assert not bus.has_type(3.0, int)
    assert not bus.has_type(True, int)
    assert bus.has_type(True, bool)
    assert bus.has_type(None, (str, type(None)))
    assert not bus.has_type(float("inf"), float)


def test_an_error_reply_may_say_when_to_ask_again():
    from toploc.bus.request_reply import _error_reply

    assert _error_reply("k", bus.error_payload("busy", 0.25)) == ("busy", 0.25)
    assert _error_reply("k", bus.error_payload("bumper pressed")) == ("bumper pressed", None)
    bad = bus.encode("error", {"error": "busy", "retry_after_s": "soon"})
    assert _error_reply("k", bad) == ("busy", None)  # not a number: no retry
    assert _error_reply("k", b"Timeout") == ("Timeout", None)  # Zenoh's own text


def test_error_payload_is_a_versioned_json_object():
    message = bus.decode("k", bus.error_payload("bumper pressed"), {"error": str})
    assert message["error"] == "bumper pressed"
    assert message["schema"] == bus.SCHEMA_VERSION
