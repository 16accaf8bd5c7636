"""Publications and the end of what a node declared: :func:`subscribe` to a key with a reader
that checks each message, :func:`undeclare_all` on close."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from typing import Any

import zenoh

from toploc.bus.errors import BusMessageError

UNDECLARE_RETRY_S = 2.0
_log = logging.getLogger(__name__)


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
