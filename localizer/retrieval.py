"""Retrieval: shortlist the stored places worth verifying, without matching every place.

Brute-force evidence matches the query against every place, so its cost grows linearly with the
map. :class:`PlaceIndex` holds one FLANN kd-tree forest (``cv2.flann_Index``) over all stacked
descriptors of a :class:`~mapdb.loading.FingerprintTable`. A query's descriptors look up their
``neighbours`` nearest map descriptors; each query descriptor then votes for the places those
neighbours belong to, with weight ``1 / (number of distinct places it hit)`` (a descriptor seen
in one place only is distinctive; one seen everywhere says little), and neighbours farther than
``max_distance_ratio`` times the descriptor's nearest distance are ignored. A place's score is its
vote total divided by ``sqrt(n_keypoints / mean_keypoints)`` so that richly textured places do not
win on the count of their chance hits. The ``k`` best scores are the shortlist.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import cv2
import numpy as np

from mapdb.records import FingerprintTable

FLANN_INDEX_KDTREE = 1


@dataclass(frozen=True)
class IndexParams:
    """FLANN and voting settings: ``trees`` in the kd forest, ``checks`` leaves searched per
    query descriptor, ``neighbours`` looked up per query descriptor, ``max_distance_ratio``
    (neighbours up to this multiple of the nearest distance vote), ``threads`` searching the
    query's descriptors at once."""

    trees: int = 4
    checks: int = 64
    neighbours: int = 8
    max_distance_ratio: float = 1.25
    threads: int = 2

    def __post_init__(self) -> None:
        if min(self.trees, self.checks, self.neighbours, self.threads) < 1:
            raise ValueError(f"trees, checks, neighbours and threads must be >= 1, got {self}")
        if not self.max_distance_ratio >= 1:
            raise ValueError(f"max_distance_ratio must be >= 1, got {self.max_distance_ratio!r}")


class PlaceIndex:
    """A nearest-neighbour index over every descriptor of a map, voting for places."""

    def __init__(
        self,
        flann: cv2.flann.Index | None,
        keypoint_place: np.ndarray,
        weights: np.ndarray,
        descriptors: np.ndarray,
        params: IndexParams,
    ) -> None:
        self._flann = flann
        self._keypoint_place = keypoint_place
        self._weights = weights
        self._descriptors = descriptors  # FLANN does not copy: keep the data alive
        self.params = params

    @classmethod
    def build(cls, table: FingerprintTable, params: IndexParams | None = None) -> PlaceIndex:
        """Index every descriptor of ``table``. An empty table gives an index with no places."""
        params = params or IndexParams()
        n_places = len(table.place_ids)
        counts = np.diff(table.offsets).astype(np.float64)
        mean = counts.mean() if n_places and counts.mean() > 0 else 1.0
        weights = 1.0 / np.sqrt(np.maximum(counts, 1.0) / mean)
        descriptors = np.ascontiguousarray(table.descriptors, dtype=np.float32)
        flann = None
        if len(descriptors) > 0:
            flann = cv2.flann.Index(
                descriptors, {"algorithm": FLANN_INDEX_KDTREE, "trees": params.trees}
            )
        return cls(flann, table.keypoint_place_index, weights, descriptors, params)

    @property
    def n_places(self) -> int:
        """Number of places in the index."""
        return len(self._weights)

    def scores(self, descriptors: np.ndarray, exclude: int | None = None) -> np.ndarray:
        """(n_places,) vote score of every place for query ``descriptors`` (n, d) float32.

        ``exclude`` (a place index) takes that place's descriptors out of the neighbours, as if
        it were not in the index (leave-one-out: a place's own descriptors are exact matches and
        would otherwise take every vote).
        """
        scores = np.zeros(self.n_places)
        descriptors = np.asarray(descriptors, dtype=np.float32)
        if self._flann is None or len(descriptors) == 0:
            return scores
        if descriptors.ndim != 2 or descriptors.shape[1] != self._descriptors.shape[1]:
            raise ValueError(
                f"query descriptors must be (n, {self._descriptors.shape[1]}), "
                f"got {descriptors.shape}"
            )
        k = min(self.params.neighbours, len(self._descriptors))
        k_search = min(2 * k if exclude is not None else k, len(self._descriptors))
        rows, dist_sq = self.search(np.ascontiguousarray(descriptors), k_search)
        if exclude is not None:
            dropped = (rows < 0) | (self._keypoint_place[np.maximum(rows, 0)] == exclude)
            dist_sq = np.where(dropped, np.inf, dist_sq)
            rows = np.where(dropped, -1, rows)
            order = np.argsort(dist_sq, axis=1, kind="stable")[:, :k]
            rows = np.take_along_axis(rows, order, axis=1)
            dist_sq = np.take_along_axis(dist_sq, order, axis=1)
        valid = (rows >= 0) & (dist_sq <= dist_sq[:, :1] * self.params.max_distance_ratio**2)
        query_of = np.broadcast_to(np.arange(len(descriptors))[:, None], rows.shape)[valid]
        place_of = self._keypoint_place[rows[valid]]
        # One vote per (query descriptor, place), split over the places it hit.
        hits = np.unique(query_of * self.n_places + place_of)
        hit_query, hit_place = np.divmod(hits, self.n_places)
        places_hit = np.bincount(hit_query, minlength=len(descriptors))
        np.add.at(scores, hit_place, 1.0 / places_hit[hit_query])
        return scores * self._weights

    def search(self, descriptors: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """``(rows, dist_sq)`` (n, k) of the ``k`` approximate nearest map descriptors of each
        row of ``descriptors``; the rows split over ``params.threads`` threads (the search is
        read-only and releases the GIL, and each row's neighbours do not depend on the split)."""
        assert self._flann is not None
        flann = self._flann

        def search(part: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            rows, dist_sq = flann.knnSearch(part, k, params={"checks": self.params.checks})
            return rows.reshape(len(part), k), dist_sq.reshape(len(part), k).astype(np.float64)

        threads = min(self.params.threads, len(descriptors))
        if threads <= 1:
            return search(descriptors)
        parts = np.array_split(descriptors, threads)
        with ThreadPoolExecutor(threads) as pool:
            found = list(pool.map(search, parts))
        return np.vstack([r for r, _ in found]), np.vstack([d for _, d in found])

    def shortlist(self, descriptors: np.ndarray, k: int, exclude: int | None = None) -> np.ndarray:
        """Indices into the table's places of the ``k`` best-voted places, best first.

        Ties are broken by place index; places without a vote are still returned if fewer
        than ``k`` got one (so an index over ``<= k`` places returns them all). ``exclude``:
        a place index left out (see :meth:`scores`).
        """
        if k < 1:
            raise ValueError(f"k must be >= 1, got {k!r}")
        scores = self.scores(descriptors, exclude)
        order = np.lexsort((np.arange(self.n_places), -scores))
        if exclude is not None:
            order = order[order != exclude]
        return order[:k]
