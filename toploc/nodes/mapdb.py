"""The map on the Zenoh bus: :class:`MapNode` answers ``map/rooms``, ``map/places`` and
``map/edges`` under ``toploc/<robot_id>/`` from a map database file.

- ``map/rooms`` -> ``{"rooms": [{"id", "name", "n_places"}]}``
- ``map/places`` (optional ``{"room": name}``) -> ``{"places": [Place fields]}``; positions in
  metres and headings in degrees in the frame of the place's room.
- ``map/edges`` -> ``{"edges": [[room_a, room_b]]}`` (the undirected room graph)

Each query opens the file read-only for its own duration: zenoh runs each queryable on a thread
of its own and an ``sqlite3`` connection may only be used by the thread that made it; a map
rebuilt while the node runs is thus served fresh. A map error becomes an error reply.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path
from typing import Any

import zenoh

from mapdb.database import MapDatabase
from toploc import bus

NODE_NAME = "mapdb"


def _json_safe(fields: dict[str, Any]) -> dict[str, Any]:
    """``fields`` with non-finite numbers as None (JSON null): a map written before non-finite
    poses were refused may hold one, and strict JSON has no NaN or inf."""
    return {
        name: None if isinstance(value, float) and not math.isfinite(value) else value
        for name, value in fields.items()
    }


class MapNode:
    """Serve the map at ``db_path`` on the bus; ``close()`` (or ``with``) to stop."""

    def __init__(self, session: zenoh.Session, robot_id: str, db_path: Path | str) -> None:
        self.session = session
        self.robot_id = bus.check_robot_id(robot_id)
        bus.ensure_unique_node(session, robot_id, NODE_NAME)
        self.db_path = Path(db_path)
        k = self.key
        self._entities: list[Any] = [
            bus.serve(session, k(bus.MAP_ROOMS), self._on_rooms),
            bus.serve(session, k(bus.MAP_PLACES), self._on_places),
            bus.serve(session, k(bus.MAP_EDGES), self._on_edges),
            session.liveliness().declare_token(bus.alive_key(robot_id, NODE_NAME)),
        ]

    def key(self, suffix: str) -> str:
        """``toploc/<robot_id>/<suffix>``."""
        return bus.key(self.robot_id, suffix)

    def close(self) -> None:
        """Undeclare everything (the session stays open)."""
        bus.undeclare_all(self._entities)

    def __enter__(self) -> MapNode:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _open(self) -> MapDatabase:
        return MapDatabase.open(self.db_path, readonly=True)

    def _on_rooms(self, _payload: bytes | None) -> bus.Reply:
        with self._open() as map_db:
            rooms = [asdict(room) for room in map_db.rooms()]
        return bus.Reply(bus.encode("rooms", {"rooms": rooms}))

    def _on_places(self, payload: bytes | None) -> bus.Reply:
        room = None
        if payload:
            request = bus.decode(self.key(bus.MAP_PLACES), payload)
            if "room" in request:
                bus.check_fields(self.key(bus.MAP_PLACES), request, {"room": str})
                room = request["room"]
        with self._open() as map_db:
            places = [_json_safe(asdict(place)) for place in map_db.places(room)]
        return bus.Reply(bus.encode("places", {"places": places}))

    def _on_edges(self, _payload: bytes | None) -> bus.Reply:
        with self._open() as map_db:
            edges = [list(edge) for edge in map_db.edges()]
        return bus.Reply(bus.encode("edges", {"edges": edges}))
