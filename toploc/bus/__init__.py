"""The Zenoh bus contract: key expressions, message schemas and their codecs, the session and its
configuration, request/reply; and the clients of the nodes (:mod:`toploc.bus.clients`).

Modules, from the ground up:

- :mod:`~toploc.bus.errors`: the exceptions (every one a :class:`BusError`);
- :mod:`~toploc.bus.keys`: ``toploc/<robot_id>/<suffix>``, a site map's
  ``toploc/map/<map_id>/<suffix>``, and the contract's key suffixes;
- :mod:`~toploc.bus.json_codec`: the JSON envelope ``{schema, kind, ...}`` and field checks;
- :mod:`~toploc.bus.png_codec`: the panorama as PNG bytes, both ways;
- :mod:`~toploc.bus.schemas`: every message's kind and fields, declared once;
- :mod:`~toploc.bus.messages`: messages to and from toploc's own types (odometry, belief, ...);
- :mod:`~toploc.bus.config`: :class:`BusConfig` from options and a user's Zenoh file;
- :mod:`~toploc.bus.session`: opening a session, one node per role and robot id;
- :mod:`~toploc.bus.access_control`: a site router's rules, one user per robot, and its
  users' Zenoh files;
- :mod:`~toploc.bus.request_reply`: queryables and queries;
- :mod:`~toploc.bus.subscriptions`: subscribers, and undeclaring what was declared;
- :mod:`~toploc.bus.clients`: what talks to each node (the nodes themselves:
  :mod:`toploc.nodes`).

This package re-exports what the nodes and commands use as ``bus.<name>`` (``from toploc import
bus``); :mod:`~toploc.bus.png_codec`, :mod:`~toploc.bus.schemas`, :mod:`~toploc.bus.messages`
and the clients are imported by name (they load OpenCV or toploc's cores).
"""

from toploc.bus.config import (
    DEFAULT_ENDPOINT,
    MODES,
    BusConfig,
    bus_config,
    client_bus_config,
    exposure_warning,
    load_zenoh_file,
)
from toploc.bus.errors import (
    BusError,
    BusIdInUse,
    BusMessageError,
    BusRateLimited,
    BusReplyError,
    BusTimeout,
    ZenohConfigError,
)
from toploc.bus.json_codec import (
    SCHEMA_VERSION,
    FieldType,
    check_fields,
    decode,
    encode,
    encode_message,
    error_payload,
    has_type,
)
from toploc.bus.keys import (
    BASE_BUMPERS,
    BASE_CMD,
    BASE_ODOM,
    BASE_STOP,
    CAMERA_CAPTURE,
    CAMERA_PANORAMA,
    FALLBACK_ROBOT_ID,
    HOMING_CANCEL,
    HOMING_GOAL,
    HOMING_PROGRESS,
    LOCALIZER_BELIEF,
    LOCALIZER_LOCALIZE,
    LOCALIZER_RESET,
    MAP_ADD,
    MAP_CHANGED,
    MAP_CONNECT,
    MAP_EDGES,
    MAP_PLACES,
    MAP_ROOMS,
    ROOT,
    SIM_KIDNAP,
    SIM_TRUE_POSE,
    SITE_CHANGES,
    SITE_ROOT,
    SITE_SNAPSHOT,
    SITE_VERSION,
    alive_key,
    check_map_id,
    check_robot_id,
    default_robot_id,
    key,
    site_alive_key,
    site_key,
)
from toploc.bus.request_reply import (
    DEFAULT_TIMEOUT_S,
    EARLY_END,
    BinaryHandler,
    Handler,
    Reply,
    request,
    request_all,
    request_json,
    serve,
    serve_binary,
    serve_replies,
)
from toploc.bus.session import (
    UNIQUE_CHECK_TIMEOUT_S,
    connected,
    ensure_unique_node,
    open_session,
    open_when_up,
    token_present,
)
from toploc.bus.subscriptions import UNDECLARE_RETRY_S, subscribe, undeclare_all

__all__ = [
    "BASE_BUMPERS",
    "BASE_CMD",
    "BASE_ODOM",
    "BASE_STOP",
    "CAMERA_CAPTURE",
    "CAMERA_PANORAMA",
    "DEFAULT_ENDPOINT",
    "DEFAULT_TIMEOUT_S",
    "EARLY_END",
    "FALLBACK_ROBOT_ID",
    "HOMING_CANCEL",
    "HOMING_GOAL",
    "HOMING_PROGRESS",
    "LOCALIZER_BELIEF",
    "LOCALIZER_LOCALIZE",
    "LOCALIZER_RESET",
    "MAP_ADD",
    "MAP_CHANGED",
    "MAP_CONNECT",
    "MAP_EDGES",
    "MAP_PLACES",
    "MAP_ROOMS",
    "MODES",
    "ROOT",
    "SCHEMA_VERSION",
    "SIM_KIDNAP",
    "SIM_TRUE_POSE",
    "SITE_CHANGES",
    "SITE_ROOT",
    "SITE_SNAPSHOT",
    "SITE_VERSION",
    "UNDECLARE_RETRY_S",
    "UNIQUE_CHECK_TIMEOUT_S",
    "BinaryHandler",
    "BusConfig",
    "BusError",
    "BusIdInUse",
    "BusMessageError",
    "BusRateLimited",
    "BusReplyError",
    "BusTimeout",
    "FieldType",
    "Handler",
    "Reply",
    "ZenohConfigError",
    "alive_key",
    "bus_config",
    "check_fields",
    "check_map_id",
    "check_robot_id",
    "client_bus_config",
    "connected",
    "decode",
    "default_robot_id",
    "encode",
    "encode_message",
    "ensure_unique_node",
    "error_payload",
    "exposure_warning",
    "has_type",
    "key",
    "load_zenoh_file",
    "open_session",
    "open_when_up",
    "request",
    "request_all",
    "request_json",
    "serve",
    "serve_binary",
    "serve_replies",
    "site_alive_key",
    "site_key",
    "subscribe",
    "token_present",
    "undeclare_all",
]
