"""The networkx view of the room graph and its GraphML export."""

from __future__ import annotations

from pathlib import Path

import networkx as nx
import pytest

from mapdb.database import MapDatabase
from mapdb.errors import MapDatabaseError
from mapdb.graph import export_graphml, graph_from_rooms, room_graph
from mapdb.records import RoomSummary


def test_room_graph_has_every_room_and_edge(filled_map: MapDatabase) -> None:
    filled_map.add_room("attic")
    graph = room_graph(filled_map)
    assert sorted(graph.nodes) == ["attic", "hall", "kitchen"]
    assert graph.nodes["kitchen"]["n_places"] == 2
    assert graph.has_edge("hall", "kitchen") and graph.has_edge("kitchen", "hall")
    assert nx.number_connected_components(graph) == 2


def test_graph_refuses_an_edge_to_a_missing_room() -> None:
    with pytest.raises(ValueError, match="'cellar'"):
        graph_from_rooms([RoomSummary(1, "hall", 0)], [("hall", "cellar")])


def test_graphml_round_trip(filled_map: MapDatabase, tmp_path: Path) -> None:
    out = tmp_path / "rooms.graphml"
    exported = export_graphml(filled_map, out)
    loaded = nx.read_graphml(out)
    assert sorted(loaded.nodes) == sorted(exported.nodes) == ["hall", "kitchen"]
    assert sorted(map(sorted, loaded.edges)) == [["hall", "kitchen"]]
    assert loaded.nodes["kitchen"]["n_places"] == 2
    assert list(tmp_path.glob("*.tmp")) == []


def test_graphml_to_missing_folder_names_the_file(filled_map: MapDatabase, tmp_path: Path) -> None:
    with pytest.raises(MapDatabaseError, match=r"cannot write .*rooms\.graphml"):
        export_graphml(filled_map, tmp_path / "no" / "such" / "rooms.graphml")
