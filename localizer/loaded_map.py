"""The map as the localizer reads it, once at start-up: :class:`LoadedMap`.

One detector's fingerprints (stacked with their rays in memory, or read from the map on
demand), the retrieval index, the places and the room graph, built from the
:class:`mapdb.records.MapSnapshot` that ``mapdb.loading`` reads. It holds no open database
handle.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import networkx as nx

from localizer.likelihood import RatioLikelihood
from localizer.retrieval import PlaceIndex, Shortlister
from localizer.routes import leg_graph
from mapdb.records import Fingerprint, FingerprintTable, MapSnapshot, Place, PlaceStore

# From this many places (twice the default shortlist) the index pays: verifying all 30 places of
# a 30-place map took 159 ms per query against 55 ms for the shortlist of 10 at 100 places
# (benchmarks/bench_real_resolution.py); below it there is little to leave out.
INDEX_MIN_PLACES = 20


@dataclass(frozen=True, eq=False)
class LoadedMap:
    """One detector's view of the map, ready to localize against: its places' fingerprints (a
    :class:`~mapdb.records.PlaceStore`: stacked in memory, or read from the map on demand), the
    places, rooms, room graph, the retrieval index and the likelihood calibrated on the map
    (None: not calibrated). Built from a :class:`mapdb.records.MapSnapshot`; holds no open
    database."""

    path: Path
    table: PlaceStore
    places: tuple[Place, ...]
    rooms: tuple[str, ...]
    edges: tuple[tuple[str, str], ...]
    index: Shortlister | None
    likelihood: RatioLikelihood | None = None

    @classmethod
    def from_snapshot(
        cls,
        snapshot: MapSnapshot,
        use_index: bool | None = None,
        index: Shortlister | None = None,
    ) -> LoadedMap:
        """The loaded map of ``snapshot`` with ``index`` (one over its places in order, e.g. a
        :class:`~localizer.retrieval.CompactPlaceIndex` for a store on disk), else (with
        ``use_index``; ``None``: from ``INDEX_MIN_PLACES`` places) a FLANN
        :class:`~localizer.retrieval.PlaceIndex` built over a table in memory."""
        table = snapshot.table
        if index is not None and index.n_places != len(table.place_ids):
            raise ValueError(
                f"the index holds {index.n_places} places, the map {snapshot.path} "
                f"{len(table.place_ids)}"
            )
        if index is None:
            if use_index is None:
                use_index = len(table.place_ids) >= INDEX_MIN_PLACES
            if use_index and not isinstance(table, FingerprintTable):
                raise ValueError("a map read from disk needs its compact index")
            if use_index:
                assert isinstance(table, FingerprintTable)
                index = PlaceIndex.build(table)
        return cls(
            path=snapshot.path,
            table=table,
            places=snapshot.places,
            rooms=snapshot.rooms,
            edges=snapshot.edges,
            index=index,
            likelihood=(
                None
                if snapshot.likelihood is None
                else RatioLikelihood.from_json(snapshot.likelihood)
            ),
        )

    @cached_property
    def places_per_room(self) -> Counter[str]:
        """How many places of each room the table holds (a room without any: 0)."""
        return Counter(self.table.rooms)

    @cached_property
    def legs(self) -> nx.Graph:
        """The places joined by the legs they were recorded on, and the legs where they pass
        each other: the graph recorded routes are found in (see
        :func:`localizer.routes.leg_graph`)."""
        return leg_graph(self.places)

    @cached_property
    def _index_of(self) -> dict[int, int]:
        return {int(place_id): i for i, place_id in enumerate(self.table.place_ids)}

    @property
    def image_size_px(self) -> tuple[int, int]:
        """``(width, height)`` of the map's panoramas (of its first place)."""
        width, height = self.table.image_sizes_px[0]
        return int(width), int(height)

    def fingerprint(self, place_id: int) -> Fingerprint:
        """The stored fingerprint of place ``place_id``; ``KeyError`` naming it if absent."""
        return self.table.fingerprint(self.table_index(place_id))

    def keypoints(self, place_id: int) -> int:
        """How many keypoints place ``place_id`` has (read from memory); ``KeyError`` if absent."""
        return int(self.table.keypoint_counts[self.table_index(place_id)])

    def place(self, place_id: int) -> Place:
        """The place with id ``place_id``; ``KeyError`` naming it if it is not in the map."""
        for place in self.places:
            if place.id == place_id:
                return place
        raise KeyError(f"place {place_id} is not in the map {self.path}")

    def table_index(self, place_id: int) -> int:
        """The index of place ``place_id`` in :attr:`table`; ``KeyError`` naming it if absent."""
        try:
            return self._index_of[int(place_id)]
        except KeyError:
            raise KeyError(f"place {place_id} is not in the map {self.path}") from None
