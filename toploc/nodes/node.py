"""What every node on the bus shares: its robot id's keys, one node of its role per robot id, the
entities it declared, and ``close()`` (or ``with``) that undeclares them. What every client of
the nodes shares is :class:`toploc.bus.clients.base.Client`."""

from __future__ import annotations

from typing import Any, Self

import zenoh

from toploc import bus


class Node:
    """A node of role ``role`` for ``robot_id`` on ``session`` (or, with ``map_id``, for a
    site map: keys under ``toploc/map/<map_id>/``).

    Refuses to start (:class:`toploc.bus.BusIdInUse`) when that role already runs for the id.
    A subclass appends what it declares to :attr:`entities`; :meth:`close` undeclares them (the
    session stays open).
    """

    def __init__(
        self, session: zenoh.Session, robot_id: str, role: str, map_id: str | None = None
    ) -> None:
        self.session = session
        self.robot_id = bus.check_robot_id(robot_id)
        self.map_id = None if map_id is None else bus.check_map_id(map_id)
        self.role = role
        bus.ensure_unique_node(session, robot_id, role, token_key=self.alive_key())
        self.entities: list[Any] = []

    def key(self, suffix: str) -> str:
        """``toploc/<robot_id>/<suffix>``; a site map's node: ``toploc/map/<map_id>/...``
        (:func:`toploc.bus.keys.site_key`)."""
        if self.map_id is not None:
            return bus.site_key(self.map_id, suffix)
        return bus.key(self.robot_id, suffix)

    def alive_key(self) -> str:
        """The node's liveliness token: ``alive/<role>`` under its keys."""
        if self.map_id is not None:
            return bus.site_alive_key(self.map_id, self.role)
        return bus.alive_key(self.robot_id, self.role)

    def close(self) -> None:
        """Undeclare everything this node declared (the session stays open)."""
        bus.undeclare_all(self.entities)

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
