"""The Zenoh bus contract: session configuration, key expressions, the JSON codec, replies.

Every key lives under ``toploc/<robot_id>/`` (see :func:`key`). Every JSON message is an object
``{"schema": SCHEMA_VERSION, "kind": <kind>, ...fields}``; an error reply (``Query.reply_err``)
is ``{"schema": 1, "kind": "error", "error": "<message>"}``. Binary payloads (the PNG panorama)
carry their metadata as a JSON attachment with the same envelope.

Threading (eclipse-zenoh 1.x, measured with 1.10.2): a plain Python function passed to
``declare_queryable``/``declare_subscriber`` is wrapped in ``zenoh.handlers.Callback(...,
indirect=True)``, which runs it on a Python thread of its own per declared entity. So a slow
queryable delays only later queries on that same key; other queryables keep answering.
:func:`serve` declares with that handler explicitly.

Querying (:func:`request`): ``Session.get`` returns at once with no reply when no queryable
matches, and with a ``ReplyError`` whose payload is ``b"Timeout"`` when one matches but does not
answer in time; both raise :class:`BusTimeout`. A query that the remote's ``access_control``
denies also returns at once with no reply (measured: no error, no ``Timeout``). A callback that
raises gets its query dropped (no reply), so :func:`serve` turns every exception into an error
reply instead.

Sessions: close every session (``with open_session(cfg) as session:``). With Python callbacks
declared, an unclosed session keeps the interpreter from exiting (the callback threads are not
daemons). Opening a peer session that connects to another peer can take up to
``scouting/delay`` (500 ms by default): that wait is what lets a query made right after
``open`` see the remote queryables (with the delay set to 0 it saw none, 0 of 10 tries).

A user's own Zenoh configuration file (``BusConfig.zenoh_file``, JSON5) brings Zenoh's
authentication (``transport/auth/usrpwd``), access control (``access_control``) and TLS;
:mod:`toploc.bus_config` decides which of toploc's options are written over it.

One node per role and robot id (:func:`ensure_unique_node`): before a node declares anything it
asks the bus for its own liveliness token; a liveliness query is answered from the declarations
the session already holds (measured: under 1 ms, whether or not a token exists). The check is
not atomic: two nodes starting within the same moment, or two sessions that connect only after
both checked (``connect`` retries, a peer that appears later), both start.
"""

from __future__ import annotations

import json
import logging
import math
import re
import socket
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zenoh

SCHEMA_VERSION = 1
ROOT = "toploc"
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
DEFAULT_TIMEOUT_S = 5.0
EARLY_END = 0.9
"""A query that ends without a reply before this fraction of its timeout was not timed out: no
queryable matched, the access control denied it, or the node asked went away (:func:`request`)."""
UNIQUE_CHECK_TIMEOUT_S = 1.0
FALLBACK_ROBOT_ID = "robot"
MODES = ("peer", "client", "router")

# Key suffixes under toploc/<robot_id>/ (see the README's bus table).
CAMERA_PANORAMA = "camera/panorama"
CAMERA_CAPTURE = "camera/capture"
BASE_CMD = "base/cmd"
BASE_STOP = "base/stop"
BASE_ODOM = "base/odom"
BASE_BUMPERS = "base/bumpers"
LOCALIZER_BELIEF = "localizer/belief"
LOCALIZER_LOCALIZE = "localizer/localize"
LOCALIZER_RESET = "localizer/reset"
MAP_ROOMS = "map/rooms"
MAP_PLACES = "map/places"
MAP_EDGES = "map/edges"
MAP_ADD = "map/add"
MAP_CONNECT = "map/connect"
MAP_CHANGED = "map/changed"
SIM_TRUE_POSE = "sim/true_pose"
"""Simulation only: the simulated base's true pose (:mod:`toploc.nodes.sim_truth`)."""
SIM_KIDNAP = "sim/kidnap"
"""Simulation only: carry the simulated base into a room (:mod:`toploc.nodes.sim_truth`)."""
HOMING_GOAL = "homing/goal"
HOMING_CANCEL = "homing/cancel"
HOMING_PROGRESS = "homing/progress"

_FORBIDDEN_CHUNK_CHARS = set("/*$?#")
_log = logging.getLogger(__name__)

FieldType = type | tuple[type, ...]


class BusError(Exception):
    """Any failure talking over the bus."""


class BusMessageError(BusError, ValueError):
    """A message that does not follow the contract (names the key and what is wrong)."""


class BusTimeout(BusError, TimeoutError):  # noqa: N818 (the name the contract uses)
    """Nobody answered a query on a key in time."""


class ZenohConfigError(BusError, ValueError):
    """A Zenoh configuration file that cannot be read (names the file and Zenoh's message)."""


class BusIdInUse(BusError):  # noqa: N818 (reads as the condition)
    """A node of the same role already runs on the bus for this robot id."""


class BusReplyError(BusError):
    """The node answered a query with an error reply; ``message`` is its text.
    ``retry_after_s``: the node refused for now (a rate limit) and will accept the same
    request after this many seconds; None for a refusal that a retry would not change."""

    def __init__(self, key_expr: str, message: str, retry_after_s: float | None = None) -> None:
        named = message if message.startswith(f"{key_expr}: ") else f"{key_expr}: {message}"
        super().__init__(named)
        self.key_expr = key_expr
        self.message = message
        self.retry_after_s = retry_after_s


class BusRateLimited(BusMessageError):  # noqa: N818 (reads as the condition)
    """Raised by a handler that refuses a request for now: the error reply carries
    ``retry_after_s`` (seconds until the same request would be accepted)."""

    def __init__(self, message: str, retry_after_s: float) -> None:
        super().__init__(message)
        self.retry_after_s = retry_after_s


def check_robot_id(robot_id: str) -> str:
    """Return ``robot_id`` if it is one non-empty key chunk (no ``/ * $ ? #``), else raise."""
    if not robot_id or _FORBIDDEN_CHUNK_CHARS & set(robot_id) or robot_id != robot_id.strip():
        raise ValueError(
            f"robot id must be a non-empty key chunk without '/', '*', '$', '?', '#' or "
            f"surrounding spaces, got {robot_id!r}"
        )
    return robot_id


def default_robot_id(hostname: str | None = None) -> str:
    """This machine's robot id: its host name (``socket.gethostname()``) up to the first dot,
    lower case, every character a key chunk forbids (``/ * $ ? #``, spaces) replaced by ``-``;
    ``"robot"`` if nothing is left. The service and the clients of one machine agree on it."""
    name = (socket.gethostname() if hostname is None else hostname).split(".")[0].lower()
    name = re.sub(r"[/*$?#\s]+", "-", name).strip("-")
    return name or FALLBACK_ROBOT_ID


def key(robot_id: str, suffix: str) -> str:
    """The key expression ``toploc/<robot_id>/<suffix>``, e.g. ``key("r1", LOCALIZER_BELIEF)``."""
    if not suffix or suffix.startswith("/") or suffix.endswith("/"):
        raise ValueError(f"key suffix must be relative like 'localizer/belief', got {suffix!r}")
    return f"{ROOT}/{check_robot_id(robot_id)}/{suffix}"


def alive_key(robot_id: str, node: str) -> str:
    """The liveliness token key of a node: ``toploc/<robot_id>/alive/<node>``."""
    return key(robot_id, f"alive/{check_robot_id(node)}")


def _one_line(zenoh_message: str) -> str:
    """Zenoh's error text on one line, without the Rust source location it ends with."""
    text = re.sub(r"\s+at \S+\.rs:\d+\.?\s*$", "", zenoh_message.strip())
    return " ".join(text.split())


def load_zenoh_file(path: Path) -> zenoh.Config:
    """Read a Zenoh configuration file (JSON5, ``zenoh.Config.from_file``); raises
    :class:`ZenohConfigError` naming the file and Zenoh's message on one line."""
    try:
        return zenoh.Config.from_file(str(path))
    except zenoh.ZError as error:
        raise ZenohConfigError(f"Zenoh configuration {path}: {_one_line(str(error))}") from None


@dataclass(frozen=True)
class BusConfig:
    """Where a session listens and connects. Defaults: a peer on 127.0.0.1:7447, no multicast,
    the robot id of this machine (:func:`default_robot_id`).

    ``listen``/``connect`` are Zenoh endpoints (``tcp/host:port``, ``udp/...``, ...). A client
    application usually listens nowhere (``listen=()``) and connects to the service.
    ``zenoh_file`` is a full Zenoh configuration (JSON5: authentication, access control, TLS)
    that the session starts from; mode, endpoints and multicast scouting are always written
    over it (:func:`toploc.bus_config.bus_config` takes them from the file where the user gave
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


def open_session(cfg: BusConfig) -> zenoh.Session:
    """Open a Zenoh session for ``cfg``; raises :class:`BusError` naming the endpoints on failure
    (e.g. the listen port is already in use). Close it with ``session.close()`` or ``with``."""
    config = cfg.to_zenoh()
    try:
        return zenoh.open(config)
    except zenoh.ZError as error:
        source = "" if cfg.zenoh_file is None else f", configuration {cfg.zenoh_file}"
        raise BusError(
            f"cannot open a Zenoh {cfg.mode} session (listen {list(cfg.listen)}, "
            f"connect {list(cfg.connect)}{source}): {_one_line(str(error))}"
        ) from error


def ensure_unique_node(
    session: zenoh.Session,
    robot_id: str,
    node: str,
    timeout_s: float = UNIQUE_CHECK_TIMEOUT_S,
) -> None:
    """Raise :class:`BusIdInUse` if the liveliness token of ``node`` for ``robot_id`` is already
    on the bus (waits at most ``timeout_s`` seconds; see the module docstring for the race).
    Call it before the node declares anything."""
    token_key = alive_key(robot_id, node)
    try:
        replies = list(session.liveliness().get(token_key, timeout=timeout_s))
    except zenoh.ZError as error:
        raise BusError(f"{token_key}: liveliness query failed: {error}") from error
    if any(reply.ok is not None for reply in replies):
        raise BusIdInUse(
            f"robot id {robot_id!r} already has a {node} node on the bus ({token_key}); "
            "choose another --robot-id"
        )


# --- codec -----------------------------------------------------------------------------------


def encode(kind: str, payload: Mapping[str, Any]) -> bytes:
    """``{"schema": SCHEMA_VERSION, "kind": kind, **payload}`` as UTF-8 JSON (strict: no NaN)."""
    clash = {"schema", "kind"} & set(payload)
    if clash:
        raise ValueError(f"{kind} message: field(s) {sorted(clash)} are reserved for the envelope")
    try:
        text = json.dumps({"schema": SCHEMA_VERSION, "kind": kind, **payload}, allow_nan=False)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{kind} message cannot be encoded as JSON: {error}") from error
    return text.encode()


def encode_message(message: Mapping[str, Any]) -> bytes:
    """A message that carries its own envelope (``schema`` and ``kind``, e.g.
    ``RoomBelief.to_json()``) as UTF-8 JSON; ``ValueError`` for another schema or no kind."""
    kind = message.get("kind")
    if message.get("schema") != SCHEMA_VERSION or not isinstance(kind, str):
        raise ValueError(
            f"a message needs schema {SCHEMA_VERSION} and a kind, got schema "
            f"{message.get('schema')!r} and kind {kind!r}"
        )
    return encode(kind, {k: v for k, v in message.items() if k not in ("schema", "kind")})


def _type_name(expected: FieldType) -> str:
    types = expected if isinstance(expected, tuple) else (expected,)
    return " or ".join("null" if t is type(None) else t.__name__ for t in types)


def has_type(value: Any, expected: FieldType) -> bool:
    """JSON-aware isinstance: an int is a float, a bool is not a number, floats must be finite."""
    types = expected if isinstance(expected, tuple) else (expected,)
    for t in types:
        if t is type(None) and value is None:
            return True
        if isinstance(value, bool) and t is not bool:
            continue
        if t is float and isinstance(value, int | float):
            return math.isfinite(value)
        if t is not type(None) and isinstance(value, t):
            return True
    return False


def check_fields(where: str, message: Mapping[str, Any], required: Mapping[str, FieldType]) -> None:
    """Raise :class:`BusMessageError` (prefixed ``where``) for a missing or ill-typed field."""
    for name, expected in required.items():
        if name not in message:
            raise BusMessageError(f"{where}: missing field {name!r} ({_type_name(expected)})")
        value = message[name]
        if not has_type(value, expected):
            raise BusMessageError(
                f"{where}: field {name!r} must be {_type_name(expected)}, got {value!r}"
            )


def _longest_string(value: Any) -> int:
    """The length of the longest string (key or value) anywhere in a parsed JSON ``value``."""
    if isinstance(value, str):
        return len(value)
    if isinstance(value, dict):
        return max((max(len(k), _longest_string(v)) for k, v in value.items()), default=0)
    if isinstance(value, list):
        return max((_longest_string(v) for v in value), default=0)
    return 0


def decode(
    key_expr: str,
    data: bytes | None,
    required: Mapping[str, FieldType] | None = None,
    kind: str | None = None,
    max_bytes: int | None = None,
    max_string_chars: int | None = None,
) -> dict[str, Any]:
    """Parse a JSON message received on ``key_expr`` and check its envelope and fields.

    ``required`` maps field name to type (``float`` accepts JSON integers; ``(dict, type(None))``
    allows null). Raises :class:`BusMessageError` naming the key: larger than ``max_bytes``, not
    UTF-8 JSON, not an object, a string longer than ``max_string_chars``, wrong ``schema``
    version, wrong ``kind`` (if given), missing or ill-typed field.
    """
    if data is None or len(data) == 0:
        raise BusMessageError(f"{key_expr}: empty payload, expected a JSON object")
    if max_bytes is not None and len(data) > max_bytes:
        raise BusMessageError(
            f"{key_expr}: payload is {len(data)} bytes; at most {max_bytes} are accepted"
        )
    try:
        message = json.loads(bytes(data).decode())
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        preview = bytes(data[:40])
        raise BusMessageError(
            f"{key_expr}: payload is not JSON ({error}; starts {preview!r})"
        ) from None
    if not isinstance(message, dict):
        raise BusMessageError(
            f"{key_expr}: payload must be a JSON object, got {type(message).__name__}"
        )
    if max_string_chars is not None and _longest_string(message) > max_string_chars:
        raise BusMessageError(
            f"{key_expr}: a string of {_longest_string(message)} characters; at most "
            f"{max_string_chars} are accepted"
        )
    schema = message.get("schema")
    if schema != SCHEMA_VERSION or isinstance(schema, bool):
        raise BusMessageError(
            f"{key_expr}: schema version {schema!r}, this toploc speaks {SCHEMA_VERSION}"
        )
    if kind is not None and message.get("kind") != kind:
        raise BusMessageError(
            f"{key_expr}: message kind {message.get('kind')!r}, expected {kind!r}"
        )
    check_fields(key_expr, message, required or {})
    return message


def error_payload(message: str, retry_after_s: float | None = None) -> bytes:
    """The body of an error reply: ``{"schema": 1, "kind": "error", "error": message}``, with
    ``"retry_after_s"`` when the refusal is for now only (a rate limit)."""
    fields: dict[str, Any] = {"error": message}
    if retry_after_s is not None:
        fields["retry_after_s"] = float(retry_after_s)
    return encode("error", fields)


# --- queryables and queries ------------------------------------------------------------------


@dataclass(frozen=True)
class Reply:
    """What a queryable handler answers: the payload and an optional attachment."""

    payload: bytes
    attachment: bytes | None = None


Handler = Callable[[bytes | None], Reply]
BinaryHandler = Callable[[bytes | None, bytes | None], Reply]
"""A handler of a binary request: ``handler(payload, attachment)`` (e.g. ``map/add``: the PNG
and its JSON metadata)."""


def _bytes(value: zenoh.ZBytes | None) -> bytes | None:
    return None if value is None else value.to_bytes()


def serve(
    session: zenoh.Session, key_expr: str, handler: Handler, threaded: bool = False
) -> zenoh.Queryable:
    """Declare a queryable on ``key_expr`` answering with ``handler(payload_bytes_or_None)``.

    Any exception in the handler becomes an error reply carrying its message (BusMessageError
    and ValueError as is, others prefixed with their type); the query is always dropped so the
    querier never waits for its timeout. Runs on the queryable's own Python thread, so queries
    on one key are answered one after another; with ``threaded``, each query is answered on a
    thread of its own as soon as it arrives (the handler then orders them itself, e.g. to drop
    those whose querier has given up while they waited).
    """
    return _declare(session, key_expr, lambda query: handler(_bytes(query.payload)), threaded)


def serve_binary(session: zenoh.Session, key_expr: str, handler: BinaryHandler) -> zenoh.Queryable:
    """:func:`serve` for a request that carries its metadata as an attachment:
    ``handler(payload, attachment)``."""

    def call(query: zenoh.Query) -> Reply:
        return handler(_bytes(query.payload), _bytes(query.attachment))

    return _declare(session, key_expr, call, threaded=False)


def _declare(
    session: zenoh.Session, key_expr: str, call: Callable[[zenoh.Query], Reply], threaded: bool
) -> zenoh.Queryable:
    def answer(query: zenoh.Query) -> None:
        with query:
            try:
                reply = call(query)
            except Exception as error:
                text = str(error)
                if not isinstance(error, ValueError):
                    text = f"{type(error).__name__}: {text}"
                _log.warning("%s: error reply: %s", key_expr, text)
                retry_after_s = error.retry_after_s if isinstance(error, BusRateLimited) else None
                try:
                    query.reply_err(error_payload(text, retry_after_s))
                except zenoh.ZError:  # session closing
                    _log.debug("%s: could not send the error reply", key_expr)
                return
            try:
                query.reply(key_expr, reply.payload, attachment=reply.attachment)
            except zenoh.ZError:  # session closing
                _log.debug("%s: could not send the reply", key_expr)

    def callback(query: zenoh.Query) -> None:
        if threaded:
            threading.Thread(target=answer, args=(query,), daemon=True).start()
        else:
            answer(query)

    return session.declare_queryable(key_expr, zenoh.handlers.Callback(callback, indirect=True))


def connected(session: zenoh.Session) -> bool:
    """Whether ``session`` has a transport to at least one other peer or router."""
    info = session.info
    return bool(info.peers_zid() or info.routers_zid())


def _error_reply(key_expr: str, data: bytes) -> tuple[str, float | None]:
    """The message of an error reply, ours (JSON ``error``) or Zenoh's own (plain text), and
    its ``retry_after_s`` (None if it has none, or it is not a finite non-negative number)."""
    try:
        fields = decode(key_expr, data, {"error": str})
    except BusMessageError:
        return data.decode(errors="replace"), None
    retry = fields.get("retry_after_s")
    if isinstance(retry, bool) or not isinstance(retry, int | float):
        return str(fields["error"]), None
    valid = math.isfinite(retry) and retry >= 0
    return str(fields["error"]), float(retry) if valid else None


def request(
    session: zenoh.Session,
    key_expr: str,
    payload: bytes | None = None,
    timeout_s: float = DEFAULT_TIMEOUT_S,
    attachment: bytes | None = None,
) -> zenoh.Sample:
    """Query ``key_expr`` (with ``payload`` and ``attachment``) and return the first good
    reply's sample.

    Raises :class:`BusTimeout` if nobody answers within ``timeout_s`` seconds (no queryable, a
    crashed handler, or too slow), :class:`BusReplyError` with the node's message for an error
    reply.
    """
    if not timeout_s > 0:
        raise ValueError(f"timeout_s must be positive, got {timeout_s!r}")
    start_s = time.monotonic()
    try:
        replies = list(
            session.get(key_expr, payload=payload, attachment=attachment, timeout=timeout_s)
        )
    except zenoh.ZError as error:
        raise BusError(f"{key_expr}: query failed: {error}") from error
    waited_s = time.monotonic() - start_s
    errors: list[str] = []
    retry_after_s: float | None = None
    for reply in replies:
        if reply.ok is not None:
            return reply.ok
        data = reply.err.payload.to_bytes() if reply.err is not None else b""
        text, retry_after_s = _error_reply(key_expr, data)
        errors.append(text)
    if not errors or errors == ["Timeout"]:
        hint = (
            "is the node running, with this robot id, and does the bus's access control "
            "allow this key?"
            if connected(session)
            else "this session reaches no other Zenoh node: is anything listening at the "
            "connect endpoints, and does it accept this session's credentials?"
        )
        if waited_s < EARLY_END * timeout_s:
            raise BusTimeout(
                f"{key_expr}: no reply after {waited_s:.1f} s (of {timeout_s:g} s allowed): no "
                f"node serves this key, or the one asked left the bus ({hint})"
            )
        raise BusTimeout(f"{key_expr}: no reply within {timeout_s:g} s ({hint})")
    raise BusReplyError(key_expr, "; ".join(errors), retry_after_s if len(errors) == 1 else None)


def request_json(
    session: zenoh.Session,
    key_expr: str,
    required: Mapping[str, FieldType],
    payload: bytes | None = None,
    timeout_s: float = DEFAULT_TIMEOUT_S,
) -> dict[str, Any]:
    """:func:`request` then :func:`decode` the reply with ``required`` fields."""
    sample = request(session, key_expr, payload, timeout_s)
    return decode(key_expr, sample.payload.to_bytes(), required)


def subscribe(
    session: zenoh.Session,
    key_expr: str,
    read: Callable[[str, bytes], Any],
    callback: Callable[[Any], object],
) -> zenoh.Subscriber:
    """Call ``callback(read(key_expr, payload))`` for each publication on ``key_expr`` (on a
    zenoh thread); one that ``read`` refuses (:class:`BusMessageError`) is logged and skipped.
    Undeclare the subscriber to stop."""

    def on_sample(sample: zenoh.Sample) -> None:
        try:
            message = read(key_expr, sample.payload.to_bytes())
        except BusMessageError as error:
            _log.warning("skipping a publication: %s", error)
            return
        callback(message)

    return session.declare_subscriber(key_expr, zenoh.handlers.Callback(on_sample))


UNDECLARE_RETRY_S = 2.0


def undeclare_all(entities: Sequence[Any]) -> None:
    """Undeclare queryables, publishers, subscribers and tokens; ignore a closed session.

    zenoh-python refuses (``RuntimeError: Already borrowed``) to undeclare an entity while
    another thread uses it, e.g. a liveliness subscriber whose callback is running: that one is
    retried for up to ``UNDECLARE_RETRY_S`` seconds.
    """
    for entity in entities:
        deadline = time.monotonic() + UNDECLARE_RETRY_S
        while True:
            try:
                entity.undeclare()
            except zenoh.ZError:
                _log.debug("undeclare after the session closed: %r", entity)
            except RuntimeError as error:
                if "borrowed" in str(error) and time.monotonic() < deadline:
                    time.sleep(0.01)
                    continue
                raise
            break
