"""What a session is configured with: :class:`BusConfig`, and one made from the command line's
options and a user's Zenoh file (:func:`bus_config`, :func:`client_bus_config`); and what such
a session exposes (:func:`exposure_warning`).

A user's own Zenoh configuration file (``BusConfig.zenoh_file``, JSON5) brings Zenoh's
authentication (``transport/auth/usrpwd``), access control (``access_control``) and TLS.
Precedence, per setting (mode, listen endpoints, connect endpoints, multicast scouting):

1. the option the user gave (``--mode``, ``--listen``, ``--connect``);
2. else the value the Zenoh file sets (a setting the file leaves out reads as ``null``, or for
   ``listen/endpoints`` as Zenoh's per-mode default, and counts as not set);
3. else toploc's default: a peer listening on ``tcp/127.0.0.1:7447`` (a client command: listening
   nowhere, connecting to ``tcp/127.0.0.1:7447``), multicast scouting off.

Everything else in the file (``transport/auth``, ``access_control``, TLS, timeouts, ...) is
Zenoh's to read. Without a file the session is exactly toploc's default.
"""

from __future__ import annotations

import ipaddress
import json
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

from toploc.bus.errors import ZenohConfigError
from toploc.bus.keys import check_robot_id, default_robot_id

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
ROS2_ROUTER_ENDPOINT = "tcp/localhost:7447"
"""Where a ROS 2 robot's Zenoh router (``ros2 run rmw_zenoh_cpp rmw_zenohd``) listens, and what
an rmw_zenoh session connects to by default (rmw_zenoh's ``DEFAULT_RMW_ZENOH_SESSION_CONFIG``)."""
ROS2_LISTEN_ENDPOINT = "tcp/127.0.0.1:0"
"""Where toploc's ROS 2 session listens by default: loopback, on a port the OS picks, as an
rmw_zenoh session does (``tcp/localhost:0``), so that the robot's ROS nodes reach it peer to
peer through the router's gossip and nothing beyond this machine does."""
MODES = ("peer", "client", "router")
_LOOPBACK_NAMES = {"localhost", "localhost.localdomain", "ip6-localhost"}


def one_line(zenoh_message: str) -> str:
    """Zenoh's error text on one line, without the Rust source location it ends with."""
    text = re.sub(r"\s+at \S+\.rs:\d+\.?\s*$", "", zenoh_message.strip())
    return " ".join(text.split())


def load_zenoh_file(path: Path) -> zenoh.Config:
    """Read a Zenoh configuration file (JSON5, ``zenoh.Config.from_file``); raises
    :class:`ZenohConfigError` naming the file and Zenoh's message on one line."""
    try:
        return zenoh.Config.from_file(str(path))
    except zenoh.ZError as error:
        raise ZenohConfigError(f"Zenoh configuration {path}: {one_line(str(error))}") from None


@dataclass(frozen=True)
class BusConfig:
    """Where a session listens and connects. Defaults: a peer on 127.0.0.1:7447, no multicast,
    the robot id of this machine (:func:`default_robot_id`).

    ``listen``/``connect`` are Zenoh endpoints (``tcp/host:port``, ``udp/...``, ...). A client
    application usually listens nowhere (``listen=()``) and connects to the service.
    ``zenoh_file`` is a full Zenoh configuration (JSON5: authentication, access control, TLS)
    that the session starts from; mode, endpoints and multicast scouting are always written
    over it (:func:`bus_config` takes them from the file where the user gave
    no option).
    """

    robot_id: str = field(default_factory=default_robot_id)
    mode: str = "peer"
    listen: tuple[str, ...] = (DEFAULT_ENDPOINT,)
    connect: tuple[str, ...] = ()
    scouting_multicast: bool = False
    zenoh_file: Path | None = None

    def __post_init__(self) -> None:
        check_robot_id(self.robot_id)
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")
        for name in ("listen", "connect"):
            endpoints = getattr(self, name)
            if isinstance(endpoints, str):
                raise ValueError(
                    f"{name} must be a list of endpoints, not the string {endpoints!r}"
                )
            bad = [e for e in endpoints if not isinstance(e, str) or "/" not in e]
            if bad:
                raise ValueError(f"{name}: {bad[0]!r} is not an endpoint like {DEFAULT_ENDPOINT!r}")
            object.__setattr__(self, name, tuple(endpoints))
        if self.mode == "client" and not self.connect:
            raise ValueError("a session in client mode needs at least one connect endpoint")

    def to_zenoh(self) -> zenoh.Config:
        """The ``zenoh.Config``: ``zenoh_file`` (or Zenoh's defaults), then this config's mode,
        endpoints and multicast scouting written over it with ``insert_json5``."""
        config = zenoh.Config() if self.zenoh_file is None else load_zenoh_file(self.zenoh_file)
        config.insert_json5("mode", json.dumps(self.mode))
        config.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
        config.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        config.insert_json5("scouting/multicast/enabled", json.dumps(self.scouting_multicast))
        return config


@dataclass(frozen=True)
class FileSettings:
    """What a Zenoh file sets of toploc's own settings; ``None`` where it sets nothing."""

    mode: str | None = None
    listen: tuple[str, ...] | None = None
    connect: tuple[str, ...] | None = None
    scouting_multicast: bool | None = None


def _json(config: zenoh.Config, key: str) -> object:
    return json.loads(config.get_json(key))


def _endpoints(value: object, mode: str) -> tuple[str, ...]:
    """A file's endpoint list, or the entry for ``mode`` of a per-mode ``{"peer": [...]}``."""
    if isinstance(value, dict):
        value = value.get(mode, [])
    if not isinstance(value, list):
        return ()
    return tuple(str(endpoint) for endpoint in value)


def file_settings(config: zenoh.Config, mode: str | None = None) -> FileSettings:
    """Read mode, endpoints and multicast scouting from a loaded Zenoh file; per-mode endpoint
    maps are read for ``mode`` (else the file's mode, else ``peer``)."""
    defaults = zenoh.Config()
    file_mode = _json(config, "mode")
    mode = mode or (str(file_mode) if file_mode else "peer")
    listen = _json(config, "listen/endpoints")
    connect = _json(config, "connect/endpoints")
    multicast = _json(config, "scouting/multicast/enabled")
    return FileSettings(
        mode=str(file_mode) if file_mode else None,
        listen=None if listen == _json(defaults, "listen/endpoints") else _endpoints(listen, mode),
        connect=_endpoints(connect, mode) or None,
        scouting_multicast=None if multicast is None else bool(multicast),
    )


def _first_given(*choices: Sequence[str] | None) -> Sequence[str]:
    """The first choice that is not ``None`` (an empty list is a choice: listen nowhere)."""
    return next(choice for choice in choices if choice is not None)


def bus_config(
    robot_id: str,
    zenoh_file: Path | None = None,
    mode: str | None = None,
    listen: Sequence[str] | None = None,
    connect: Sequence[str] | None = None,
) -> BusConfig:
    """The service's session: each of ``mode``/``listen``/``connect`` given wins, else the
    file's, else toploc's default (see the module docstring). Raises ``ValueError`` (a
    :class:`~toploc.bus.errors.ZenohConfigError` for an unreadable file)."""
    found = FileSettings()
    if zenoh_file is not None:
        found = file_settings(load_zenoh_file(zenoh_file), mode)
    return BusConfig(
        robot_id=robot_id,
        mode=mode or found.mode or "peer",
        listen=tuple(_first_given(listen, found.listen, (DEFAULT_ENDPOINT,))),
        connect=tuple(connect if connect is not None else found.connect or ()),
        scouting_multicast=bool(found.scouting_multicast),
        zenoh_file=zenoh_file,
    )


def client_bus_config(
    robot_id: str,
    zenoh_file: Path | None = None,
    connect: Sequence[str] | None = None,
) -> BusConfig:
    """A client command's session: listens nowhere (whatever the file says), connects to
    ``connect``, else the file's endpoints, else ``tcp/127.0.0.1:7447``; mode the file's, else
    peer."""
    found = FileSettings() if zenoh_file is None else file_settings(load_zenoh_file(zenoh_file))
    return BusConfig(
        robot_id=robot_id,
        mode=found.mode or "peer",
        listen=(),
        connect=tuple(connect if connect is not None else found.connect or (DEFAULT_ENDPOINT,)),
        scouting_multicast=bool(found.scouting_multicast),
        zenoh_file=zenoh_file,
    )


def ros2_bus_config(
    robot_id: str,
    zenoh_file: Path | None = None,
    connect: Sequence[str] | None = None,
    listen: Sequence[str] | None = None,
) -> BusConfig:
    """The session that joins a ROS 2 graph over rmw_zenoh: a peer of the robot's Zenoh router,
    connecting to ``connect``, else the file's, else :data:`ROS2_ROUTER_ENDPOINT`; listening on
    ``listen``, else the file's, else :data:`ROS2_LISTEN_ENDPOINT`; multicast scouting off (as
    rmw_zenoh's; the router's gossip finds the peers)."""
    found = FileSettings() if zenoh_file is None else file_settings(load_zenoh_file(zenoh_file))
    return BusConfig(
        robot_id=robot_id,
        mode=found.mode or "peer",
        listen=tuple(_first_given(listen, found.listen, (ROS2_LISTEN_ENDPOINT,))),
        connect=tuple(connect if connect is not None else found.connect or (ROS2_ROUTER_ENDPOINT,)),
        scouting_multicast=bool(found.scouting_multicast),
        zenoh_file=zenoh_file,
    )


def endpoint_host(endpoint: str) -> str | None:
    """The host of a network endpoint (``tcp/[::1]:7447`` -> ``::1``), ``None`` for one that
    names no host and port (``unixsock-stream/...``)."""
    address = endpoint.split("/", 1)[1] if "/" in endpoint else endpoint
    address = address.split("?", 1)[0].split("#", 1)[0]
    if address.startswith("["):
        host, bracket, _ = address[1:].partition("]")
        return host if bracket else None
    host, colon, port = address.rpartition(":")
    return host if colon and port.isdigit() and host else None


def is_loopback(endpoint: str) -> bool:
    """Whether ``endpoint`` can only be reached from this machine: a host in 127.0.0.0/8,
    ``::1`` or ``localhost``, or an endpoint without a host (a Unix socket)."""
    host = endpoint_host(endpoint)
    if host is None:
        return endpoint.split("/", 1)[0] not in ("tcp", "udp", "tls", "quic", "ws")
    if host.lower() in _LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host.split("%", 1)[0]).is_loopback
    except ValueError:  # a host name other than localhost: may be any interface
        return False


def authenticates_peers(config: zenoh.Config) -> bool:
    """Whether a session with ``config`` checks who connects to it: a ``usrpwd``
    ``dictionary_file``, or TLS with client certificates (``enable_mtls``)."""
    dictionary = _json(config, "transport/auth/usrpwd/dictionary_file")
    mtls = _json(config, "transport/link/tls/enable_mtls")
    return bool(dictionary) or mtls is True


def exposure_warning(cfg: BusConfig) -> str | None:
    """A warning if ``cfg`` listens beyond loopback while nothing authenticates who connects
    (then anyone who reaches the port may command the robot), else ``None``."""
    exposed = [endpoint for endpoint in cfg.listen if not is_loopback(endpoint)]
    if not exposed or authenticates_peers(cfg.to_zenoh()):
        return None
    return (
        f"listening on {exposed} beyond this machine without authentication: anyone who "
        "reaches it can command the robot. Pass --zenoh-config with transport/auth/usrpwd "
        "(dictionary_file) or mTLS, and an access_control (docs/security.md)."
    )
