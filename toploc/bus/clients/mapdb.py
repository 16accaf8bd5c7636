"""The map's clients: :class:`MapClient` queries and extends the map a
:class:`~toploc.nodes.mapdb.MapNode` serves, :func:`subscribe_changes` follows its
``map/changed``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import zenoh

from mapdb.records import Leg
from toploc import bus
from toploc.bus.clients.base import Client
from toploc.bus.schemas import ADD, ADDED, CHANGED, CONNECT, CONNECTED, PLACES, PLACES_QUERY

ADD_TIMEOUT_S = 60.0
"""How long :meth:`MapClient.add` waits: sending a large PNG and extracting its features."""


def subscribe_changes(
    session: zenoh.Session, robot_id: str, on_change: Callable[[], None]
) -> zenoh.Subscriber:
    """Call ``on_change()`` for each well-formed ``map/changed`` of ``robot_id``'s map node
    (a malformed one is ignored); undeclare the subscriber to stop."""
    return bus.subscribe(
        session,
        bus.key(robot_id, bus.MAP_CHANGED),
        lambda key_expr, data: CHANGED.decode(key_expr, data),
        lambda _message: on_change(),
    )


class MapClient(Client):
    """Query and extend the map of robot ``robot_id`` over ``session``.

    Every call raises :class:`~toploc.bus.BusTimeout` if no map node answers in time,
    :class:`~toploc.bus.BusReplyError` with the node's message for an error reply.
    """

    def __init__(
        self,
        session: zenoh.Session,
        robot_id: str,
        timeout_s: float = bus.DEFAULT_TIMEOUT_S,
        add_timeout_s: float = ADD_TIMEOUT_S,
    ) -> None:
        super().__init__(session, robot_id, timeout_s)
        self.add_timeout_s = add_timeout_s

    def add(
        self,
        png: bytes,
        room: str,
        x_m: float | None = None,
        y_m: float | None = None,
        heading_deg: float | None = None,
        leg: Leg | None = None,
    ) -> dict[str, Any]:
        """Add the panorama ``png`` as a place of ``room`` (pose optional, in the room's frame,
        or another frame the caller documents: an odometry pose, with the ``leg`` driven from
        the place recorded before); the reply (``place_id``, ``new``, ...)."""
        meta: dict[str, Any] = {"room": room}
        for name, value in (("x_m", x_m), ("y_m", y_m), ("heading_deg", heading_deg)):
            if value is not None:
                meta[name] = value
        if leg is not None:
            meta["leg_from"] = leg.from_place
            meta["leg_via"] = [list(point) for point in leg.via_xy_m]
        key_expr = self.key(bus.MAP_ADD)
        sample = bus.request(
            self.session, key_expr, png, self.add_timeout_s, attachment=ADD.encode(meta)
        )
        return ADDED.decode(key_expr, sample.payload.to_bytes(), check_kind=False)

    def connect(self, room_a: str, room_b: str) -> dict[str, Any]:
        """Add the room-graph edge ``room_a`` -- ``room_b``; the reply (``added``)."""
        payload = CONNECT.encode({"room_a": room_a, "room_b": room_b})
        key_expr = self.key(bus.MAP_CONNECT)
        return bus.request_json(self.session, key_expr, CONNECTED.fields, payload, self.timeout_s)

    def places(self, room: str | None = None) -> list[dict[str, Any]]:
        """The map's places (of ``room`` if given)."""
        payload = None if room is None else PLACES_QUERY.encode({"room": room})
        key_expr = self.key(bus.MAP_PLACES)
        reply = bus.request_json(self.session, key_expr, PLACES.fields, payload, self.timeout_s)
        return list(reply["places"])
