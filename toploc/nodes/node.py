"""What every node on the bus shares: its robot id's keys, one node of its role per robot id, the
entities it declared, and ``close()`` (or ``with``) that undeclares them. What every client of
the nodes shares is :class:`toploc.bus.clients.base.Client`."""

from __future__ import annotations

from typing import Any, Self

import zenoh

from toploc import bus


class Node:
    """A node of role ``role`` for ``robot_id`` on ``session``.

    Refuses to start (:class:`toploc.bus.BusIdInUse`) when that role already runs for the id.
    A subclass appends what it declares to :attr:`entities`; :meth:`close` undeclares them (the
    session stays open).
    """

    def __init__(self, session: zenoh.Session, robot_id: str, role: str) -> None:
        self.session = session
        self.robot_id = bus.check_robot_id(robot_id)
        bus.ensure_unique_node(session, robot_id, role)
        self.entities: list[Any] = []

    def key(self, suffix: str) -> str:
        """``toploc/<robot_id>/<suffix>``."""
        return bus.key(self.robot_id, suffix)

    def close(self) -> None:
        """Undeclare everything this node declared (the session stays open)."""
        bus.undeclare_all(self.entities)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
