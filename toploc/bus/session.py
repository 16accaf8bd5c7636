"""Opening a Zenoh session for a :class:`~toploc.bus.config.BusConfig`, and one node per role and
robot id.

Sessions: close every session (``with open_session(cfg) as session:``). With Python callbacks
declared, an unclosed session keeps the interpreter from exiting (the callback threads are not
daemons). Opening a peer session that connects to another peer can take up to
``scouting/delay`` (500 ms by default): that wait is what lets a query made right after
``open`` see the remote queryables (with the delay set to 0 it saw none, 0 of 10 tries).

One node per role and robot id (:func:`ensure_unique_node`): before a node declares anything it
asks the bus for its own liveliness token; a liveliness query is answered from the declarations
the session already holds (measured: under 1 ms, whether or not a token exists). The check is
not atomic: two nodes starting within the same moment, or two sessions that connect only after
both checked (``connect`` retries, a peer that appears later), both start.
"""

from __future__ import annotations

import threading

import zenoh

from toploc.bus.config import BusConfig, one_line
from toploc.bus.errors import BusError, BusIdInUse
from toploc.bus.keys import alive_key

UNIQUE_CHECK_TIMEOUT_S = 1.0


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
            f"connect {list(cfg.connect)}{source}): {one_line(str(error))}"
        ) from error


def ensure_unique_node(
    session: zenoh.Session,
    robot_id: str,
    node: str,
    timeout_s: float = UNIQUE_CHECK_TIMEOUT_S,
    token_key: str | None = None,
) -> None:
    """Raise :class:`BusIdInUse` if the liveliness token of ``node`` for ``robot_id`` (or
    ``token_key``, a site map's) is already on the bus (waits at most ``timeout_s`` seconds; see
    the module docstring for the race). Call it before the node declares anything."""
    token_key = token_key or alive_key(robot_id, node)
    if token_present(session, token_key, timeout_s):
        what, option = (
            (f"robot id {robot_id!r}", "--robot-id")
            if token_key == alive_key(robot_id, node)
            else ("this map id", "--map-id")
        )
        raise BusIdInUse(
            f"{what} already has a {node} node on the bus ({token_key}); choose another {option}"
        )


def token_present(session: zenoh.Session, token_key: str, timeout_s: float) -> bool:
    """Whether a liveliness token matching ``token_key`` is on the bus, as a query that waits at
    most ``timeout_s`` seconds finds; :class:`BusError` naming the key if the query fails."""
    try:
        replies = list(session.liveliness().get(token_key, timeout=timeout_s))
    except zenoh.ZError as error:
        raise BusError(f"{token_key}: liveliness query failed: {error}") from error
    return any(reply.ok is not None for reply in replies)


def connected(session: zenoh.Session) -> bool:
    """Whether ``session`` has a transport to at least one other peer or router."""
    info = session.info
    return bool(info.peers_zid() or info.routers_zid())


def open_when_up(
    config: BusConfig, stop: threading.Event, retry_s: float = 0.5
) -> zenoh.Session | None:
    """A session of ``config`` (a Zenoh client: it cannot open before the service it connects
    to listens), tried every ``retry_s`` until it opens; None if ``stop`` is set first."""
    while True:
        try:
            return open_session(config)
        except BusError:
            if stop.wait(retry_s):
                return None
