"""What every client of a robot's nodes shares: the keys, a query timeout and the subscribers it
made."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Self

import zenoh

from toploc import bus


class Client:
    """A client of robot ``robot_id``'s nodes on ``session``, whose queries wait up to
    ``timeout_s`` seconds. :meth:`close` (or ``with``) undeclares the subscribers it made (the
    session stays open)."""

    def __init__(
        self, session: zenoh.Session, robot_id: str, timeout_s: float = bus.DEFAULT_TIMEOUT_S
    ) -> None:
        self.session = session
        self.robot_id = bus.check_robot_id(robot_id)
        self.timeout_s = timeout_s
        self.subscribers: list[Any] = []

    def key(self, suffix: str) -> str:
        """``toploc/<robot_id>/<suffix>``."""
        return bus.key(self.robot_id, suffix)

    def _subscribe(
        self,
        suffix: str,
        read: Callable[[str, bytes], Any],
        callback: Callable[[Any], object],
    ) -> zenoh.Subscriber:
        """:func:`toploc.bus.subscribe` to this robot's ``suffix``, kept for :meth:`close`."""
        subscriber = bus.subscribe(self.session, self.key(suffix), read, callback)
        self.subscribers.append(subscriber)
        return subscriber

    def close(self) -> None:
        """Undeclare the subscribers this client made."""
        bus.undeclare_all(self.subscribers)
        self.subscribers.clear()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
