"""Request and reply over the bus: a queryable's side (:func:`serve`, :class:`Reply`) and the
querier's (:func:`request`, :func:`request_json`).

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
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import zenoh

from toploc.bus.errors import (
    BusError,
    BusMessageError,
    BusRateLimited,
    BusReplyError,
    BusTimeout,
)
from toploc.bus.json_codec import FieldType, decode, error_payload
from toploc.bus.schemas import ERROR
from toploc.bus.session import connected

DEFAULT_TIMEOUT_S = 5.0
EARLY_END = 0.9
"""A query that ends without a reply before this fraction of its timeout was not timed out: no
queryable matched, the access control denied it, or the node asked went away (:func:`request`)."""
_log = logging.getLogger(__name__)


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


def serve_replies(
    session: zenoh.Session, key_expr: str, handler: Callable[[bytes | None], list[Reply]]
) -> zenoh.Queryable:
    """:func:`serve` for a handler that answers one query with several replies (the chunks of a
    snapshot), sent in order; the querier collects them with :func:`request_all`. An
    exception before the first reply is an error reply."""

    def answer(query: zenoh.Query) -> None:
        with query:
            try:
                replies = handler(_bytes(query.payload))
            except Exception as error:
                text = str(error)
                if not isinstance(error, ValueError):
                    text = f"{type(error).__name__}: {text}"
                _log.warning("%s: error reply: %s", key_expr, text)
                try:
                    query.reply_err(error_payload(text))
                except zenoh.ZError:
                    _log.debug("%s: could not send the error reply", key_expr)
                return
            try:
                for reply in replies:
                    query.reply(key_expr, reply.payload, attachment=reply.attachment)
            except zenoh.ZError:  # session closing
                _log.debug("%s: could not send every reply", key_expr)

    return session.declare_queryable(key_expr, zenoh.handlers.Callback(answer, indirect=True))


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


def _error_reply(key_expr: str, data: bytes) -> tuple[str, float | None]:
    """The message of an error reply, ours (JSON ``error``) or Zenoh's own (plain text), and
    its ``retry_after_s`` (None if it has none, or it is not a finite non-negative number)."""
    try:
        fields = ERROR.decode(key_expr, data, check_kind=False)
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


def request_all(
    session: zenoh.Session,
    key_expr: str,
    payload: bytes | None = None,
    timeout_s: float = DEFAULT_TIMEOUT_S,
) -> list[zenoh.Sample]:
    """Every reply to one query of ``key_expr`` (none consolidated away), in arrival order;
    :class:`BusTimeout` without any, :class:`BusReplyError` for an error reply."""
    if not timeout_s > 0:
        raise ValueError(f"timeout_s must be positive, got {timeout_s!r}")
    try:
        replies = list(
            session.get(
                key_expr, payload=payload, timeout=timeout_s,
                consolidation=zenoh.ConsolidationMode.NONE,
            )
        )  # fmt: skip
    except zenoh.ZError as error:
        raise BusError(f"{key_expr}: query failed: {error}") from error
    samples = [reply.ok for reply in replies if reply.ok is not None]
    errors = [
        _error_reply(key_expr, reply.err.payload.to_bytes())[0]
        for reply in replies
        if reply.ok is None and reply.err is not None
    ]
    if errors and errors != ["Timeout"]:
        raise BusReplyError(key_expr, "; ".join(errors), None)
    if not samples:
        raise BusTimeout(f"{key_expr}: no reply within {timeout_s:g} s (is the node running?)")
    return samples


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
