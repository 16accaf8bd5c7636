"""The errors of the bus: every failure talking over Zenoh is a :class:`BusError`."""

from __future__ import annotations


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
