"""The room graph as a networkx view, and its GraphML export.

Nodes are room names (attributes ``room_id``, ``n_places``); an undirected edge joins two rooms
the robot can drive between. The view is a copy: changing it does not change the database.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

import networkx as nx

from mapdb.database import MapDatabase
from mapdb.errors import MapDatabaseError
from mapdb.records import RoomSummary


def graph_from_rooms(rooms: Iterable[RoomSummary], edges: Iterable[tuple[str, str]]) -> nx.Graph:
    """Build the undirected room graph from room summaries and name pairs (pure)."""
    graph: nx.Graph[str] = nx.Graph()
    for room in rooms:
        graph.add_node(room.name, room_id=room.id, n_places=room.n_places)
    for room_a, room_b in edges:
        if room_a not in graph or room_b not in graph:
            raise ValueError(f"edge ({room_a!r}, {room_b!r}) names a room that is not a node")
        graph.add_edge(room_a, room_b)
    return graph


def connect_known_rooms(map_db: MapDatabase, edges: Iterable[tuple[str, str]]) -> int:
    """Add the edges whose two rooms are in the map (e.g. a dataset's ``edges.csv``, of which
    some rooms may have no panorama); return how many were new."""
    known = {room.name for room in map_db.rooms()}
    return sum(map_db.connect_rooms(a, b) for a, b in edges if a in known and b in known)


def room_graph(map_db: MapDatabase) -> nx.Graph:
    """The room graph of ``map_db`` (every room is a node, connected or not)."""
    return graph_from_rooms(map_db.rooms(), map_db.edges())


def export_graphml(map_db: MapDatabase, out_path: Path | str) -> nx.Graph:
    """Write the room graph to ``out_path`` as GraphML (atomically: temp file, then rename).

    Returns the exported graph. Raises :class:`MapDatabaseError` naming ``out_path`` if it
    cannot be written.
    """
    out_path = Path(out_path)
    graph = room_graph(map_db)
    try:
        fd, tmp_name = tempfile.mkstemp(
            prefix=out_path.name + ".", suffix=".tmp", dir=out_path.parent
        )
    except OSError as error:
        raise MapDatabaseError(f"cannot write {out_path}: {error.strerror}", out_path) from error
    try:
        with os.fdopen(fd, "wb") as handle:
            nx.write_graphml(graph, handle)
        os.replace(tmp_name, out_path)
    except OSError as error:
        Path(tmp_name).unlink(missing_ok=True)
        raise MapDatabaseError(f"cannot write {out_path}: {error.strerror}", out_path) from error
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise
    return graph
