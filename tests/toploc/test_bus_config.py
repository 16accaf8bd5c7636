"""A session's configuration from options and a Zenoh file, without a network: precedence, bad
files, the default robot id, which endpoints reach beyond loopback."""

import json

import pytest

from toploc import bus
from toploc.bus.config import (
    bus_config,
    client_bus_config,
    endpoint_host,
    exposure_warning,
    is_loopback,
)


def zenoh_json(cfg: bus.BusConfig, key: str) -> object:
    return json.loads(cfg.to_zenoh().get_json(key))


@pytest.fixture
def file_with_everything(tmp_path):
    path = tmp_path / "zenoh.json5"
    path.write_text(
        """{ // a comment: JSON5
          mode: "router",
          listen: { endpoints: ["tcp/127.0.0.1:7450"] },
          connect: { endpoints: ["tcp/127.0.0.1:7451"] },
          scouting: { multicast: { enabled: true } },
          queries_default_timeout: 1234,
        }"""
    )
    return path


def test_without_a_file_the_session_is_exactly_the_default():
    assert bus_config("r1") == bus.BusConfig("r1")
    assert client_bus_config("r1") == bus.BusConfig(
        "r1", listen=(), connect=(bus.DEFAULT_ENDPOINT,)
    )


def test_the_file_wins_over_toploc_defaults_and_keeps_its_other_settings(file_with_everything):
    cfg = bus_config("r1", file_with_everything)
    assert (cfg.mode, cfg.listen, cfg.connect) == (
        "router",
        ("tcp/127.0.0.1:7450",),
        ("tcp/127.0.0.1:7451",),
    )
    assert cfg.scouting_multicast is True
    assert zenoh_json(cfg, "queries_default_timeout") == 1234
    assert zenoh_json(cfg, "listen/endpoints") == ["tcp/127.0.0.1:7450"]


def test_options_given_win_over_the_file(file_with_everything):
    cfg = bus_config("r1", file_with_everything, "peer", ["tcp/127.0.0.1:7460"], ["tcp/h:1"])
    assert (cfg.mode, cfg.listen, cfg.connect) == ("peer", ("tcp/127.0.0.1:7460",), ("tcp/h:1",))
    assert zenoh_json(cfg, "mode") == "peer"
    assert zenoh_json(cfg, "connect/endpoints") == ["tcp/h:1"]


def test_a_client_never_listens_but_takes_the_files_endpoints(file_with_everything):
    cfg = client_bus_config("r1", file_with_everything)
    assert (cfg.listen, cfg.connect) == ((), ("tcp/127.0.0.1:7451",))
    assert client_bus_config("r1", file_with_everything, ["tcp/h:2"]).connect == ("tcp/h:2",)


def test_what_the_file_leaves_out_is_toplocs_default(tmp_path):
    path = tmp_path / "auth.json5"
    path.write_text('{transport: {auth: {usrpwd: {user: "u", password: "p"}}}}')
    cfg = bus_config("r1", path)
    assert (cfg.mode, cfg.listen, cfg.connect) == ("peer", (bus.DEFAULT_ENDPOINT,), ())
    assert zenoh_json(cfg, "scouting/multicast/enabled") is False
    assert zenoh_json(cfg, "transport/auth/usrpwd/user") == "u"


def test_per_mode_endpoints_are_read_for_the_mode(tmp_path):
    path = tmp_path / "modes.json5"
    path.write_text('{listen: {endpoints: {peer: ["tcp/127.0.0.1:7452"], router: []}}}')
    assert bus_config("r1", path).listen == ("tcp/127.0.0.1:7452",)
    assert bus_config("r1", path, mode="router").listen == ()


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('{mode: "bogus"}', "unknown variant `bogus`"),
        ("{foo: 1}", "unknown field `foo`"),
        ("{mode: ", r"bad\.json5: "),
    ],
)
def test_a_bad_file_is_one_line_naming_the_file_and_zenohs_message(tmp_path, text, match):
    path = tmp_path / "bad.json5"
    path.write_text(text)
    with pytest.raises(bus.ZenohConfigError, match=match) as raised:
        bus_config("r1", path)
    message = str(raised.value)
    assert message.startswith(f"Zenoh configuration {path}: ")
    assert "\n" not in message and ".rs:" not in message


def test_a_missing_file_names_the_file(tmp_path):
    with pytest.raises(bus.ZenohConfigError, match=r"missing\.json5: No such file"):
        client_bus_config("r1", tmp_path / "missing.json5")


@pytest.mark.parametrize(
    ("hostname", "robot_id"),
    [
        ("pioneer-3.lab.example.org", "pioneer-3"),
        ("Robot One", "robot-one"),
        ("a/b*c$d?e#f", "a-b-c-d-e-f"),
        ("", "robot"),
        ("***", "robot"),
    ],
)
def test_the_default_robot_id_is_the_sanitised_host_name(hostname, robot_id):
    assert bus.default_robot_id(hostname) == robot_id
    assert bus.check_robot_id(bus.default_robot_id(hostname)) == robot_id


def test_configs_default_to_this_machines_robot_id():
    assert bus.BusConfig().robot_id == bus.default_robot_id()


@pytest.mark.parametrize(
    ("endpoint", "host", "loopback"),
    [
        ("tcp/127.0.0.1:7447", "127.0.0.1", True),
        ("tcp/127.3.2.1:7447", "127.3.2.1", True),
        ("udp/[::1]:7447", "::1", True),
        ("tcp/localhost:7447", "localhost", True),
        ("tcp/0.0.0.0:7447", "0.0.0.0", False),
        ("tcp/[::]:7447", "::", False),
        ("tls/192.168.1.5:7447", "192.168.1.5", False),
        ("tcp/robot.local:7447#iface=eth0", "robot.local", False),
        ("unixsock-stream//tmp/toploc.sock", None, True),
    ],
)
def test_loopback_endpoints(endpoint, host, loopback):
    assert endpoint_host(endpoint) == host
    assert is_loopback(endpoint) is loopback


def test_listening_beyond_loopback_warns_unless_peers_must_authenticate(tmp_path):
    exposed = bus.BusConfig("r1", listen=("tcp/127.0.0.1:7447", "tcp/0.0.0.0:7448"))
    warning = exposure_warning(exposed)
    assert warning is not None and "['tcp/0.0.0.0:7448']" in warning and "usrpwd" in warning
    assert exposure_warning(bus.BusConfig("r1")) is None
    dictionary = tmp_path / "credentials.txt"
    dictionary.write_text("operator:secret\n")
    path = tmp_path / "auth.json5"
    path.write_text(
        json.dumps({"transport": {"auth": {"usrpwd": {"dictionary_file": str(dictionary)}}}})
    )
    assert exposure_warning(bus_config("r1", path, listen=["tcp/0.0.0.0:7448"])) is None
    only_a_password = tmp_path / "client.json5"
    only_a_password.write_text('{transport: {auth: {usrpwd: {user: "u", password: "p"}}}}')
    assert exposure_warning(bus_config("r1", only_a_password, listen=["tcp/[::]:7448"])) is not None
