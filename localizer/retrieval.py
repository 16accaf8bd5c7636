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

:class:`CompactPlaceIndex` votes the same way over product-quantised codes (faiss IVF-PQ, fast-scan
4-bit codes by default), and
its ids are the place indices, so it holds no descriptor and no per-keypoint row: about 24 bytes
per map keypoint (16 bytes of code and faiss's 8-byte id) against the 512 bytes of a float32
descriptor plus FLANN's forest. Its coarse quantiser and codebooks are trained once on a
sample of the map's descriptors; places added later are encoded with them, with no retraining
(:meth:`CompactPlaceIndex.add_place`). Both are a :class:`Shortlister`.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Any, Protocol

import cv2
import faiss
import numpy as np

from mapdb.records import FingerprintTable

FLANN_INDEX_KDTREE = 1


@dataclass(frozen=True)
class IndexParams:
    """FLANN and voting settings: ``trees`` in the kd forest, ``checks`` leaves searched per
    query descriptor, ``neighbours`` looked up per query descriptor, ``max_distance_ratio``
    (neighbours up to this multiple of the nearest distance vote), ``threads`` searching the
    query's descriptors at once, ``seed`` of the forest's random splits: FLANN draws them from
    the building thread's OpenCV RNG, so unseeded a forest built after anything else had drawn
    from it (a second index in one process, a service re-reading its map after ``map/add``)
    differed from one built first, and so did its shortlists."""

    trees: int = 4
    checks: int = 64
    neighbours: int = 8
    max_distance_ratio: float = 1.25
    threads: int = 2
    seed: int = 0

    def __post_init__(self) -> None:
        if min(self.trees, self.checks, self.neighbours, self.threads) < 1:
            raise ValueError(f"trees, checks, neighbours and threads must be >= 1, got {self}")
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0, got {self.seed}")
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
        weights = place_weights(np.diff(table.offsets))
        descriptors = np.ascontiguousarray(table.descriptors, dtype=np.float32)
        flann = None
        if len(descriptors) > 0:
            cv2.setRNGSeed(params.seed)  # the forest's splits come from this thread's RNG
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
        descriptors = np.asarray(descriptors, dtype=np.float32)
        if self._flann is None or len(descriptors) == 0:
            return np.zeros(self.n_places)
        check_query(descriptors, self._descriptors.shape[1])
        k = min(self.params.neighbours, len(self._descriptors))
        k_search = min(2 * k if exclude is not None else k, len(self._descriptors))
        rows, dist_sq = self.search(np.ascontiguousarray(descriptors), k_search)
        place_of = np.where(rows >= 0, self._keypoint_place[np.maximum(rows, 0)], -1)
        return vote(place_of, dist_sq, self._weights, self.params.max_distance_ratio, k, exclude)

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
        """Indices into the table's places of the ``k`` best-voted places, best first (see
        :func:`best_places`)."""
        return best_places(self.scores(descriptors, exclude), k, exclude)


def check_query(descriptors: np.ndarray, dim: int) -> None:
    """``ValueError`` unless ``descriptors`` is (n, ``dim``)."""
    if descriptors.ndim != 2 or descriptors.shape[1] != dim:
        raise ValueError(f"query descriptors must be (n, {dim}), got {descriptors.shape}")


def place_weights(counts: np.ndarray) -> np.ndarray:
    """(m,) each place's vote weight ``1 / sqrt(n_keypoints / mean)`` for its keypoint
    ``counts`` (a place without keypoints counts as one)."""
    counts = np.asarray(counts, dtype=np.float64)
    mean = counts.mean() if len(counts) and counts.mean() > 0 else 1.0
    return 1.0 / np.sqrt(np.maximum(counts, 1.0) / mean)


def vote(
    place_of: np.ndarray,
    dist_sq: np.ndarray,
    weights: np.ndarray,
    max_distance_ratio: float,
    k: int,
    exclude: int | None = None,
) -> np.ndarray:
    """(m,) vote score of every place from each query descriptor's neighbours.

    ``place_of`` (n, k') int: the place index of each query descriptor's neighbours, nearest
    first (-1: none), ``dist_sq`` (n, k') their squared distances; ``weights`` (m,)
    (:func:`place_weights`). ``exclude``'s neighbours are dropped first; then the ``k``
    nearest left vote if within ``max_distance_ratio`` times the nearest distance, each
    query descriptor one vote per place it hit, split over those places.
    """
    n_places = len(weights)
    scores = np.zeros(n_places)
    dist_sq = np.asarray(dist_sq, dtype=np.float64)
    if exclude is not None:
        dropped = (place_of < 0) | (place_of == exclude)
        dist_sq = np.where(dropped, np.inf, dist_sq)
        place_of = np.where(dropped, -1, place_of)
        order = np.argsort(dist_sq, axis=1, kind="stable")[:, :k]
        place_of = np.take_along_axis(place_of, order, axis=1)
        dist_sq = np.take_along_axis(dist_sq, order, axis=1)
    place_of, dist_sq = place_of[:, :k], dist_sq[:, :k]
    valid = (place_of >= 0) & (dist_sq <= dist_sq[:, :1] * max_distance_ratio**2)
    n_query = len(place_of)
    query_of = np.broadcast_to(np.arange(n_query)[:, None], place_of.shape)[valid]
    # One vote per (query descriptor, place), split over the places it hit.
    hits = np.unique(query_of * n_places + place_of[valid])
    hit_query, hit_place = np.divmod(hits, n_places)
    places_hit = np.bincount(hit_query, minlength=n_query)
    np.add.at(scores, hit_place, 1.0 / places_hit[hit_query])
    return scores * weights


def best_places(scores: np.ndarray, k: int, exclude: int | None = None) -> np.ndarray:
    """Indices of the ``k`` best ``scores``, best first.

    Ties are broken by place index; places without a vote are still returned if fewer
    than ``k`` got one (so an index over ``<= k`` places returns them all). ``exclude``:
    a place index left out.
    """
    if k < 1:
        raise ValueError(f"k must be >= 1, got {k!r}")
    order = np.lexsort((np.arange(len(scores)), -scores))
    if exclude is not None:
        order = order[order != exclude]
    return order[:k]


class Shortlister(Protocol):
    """What evidence asks of a retrieval index: the places worth verifying for a query."""

    @property
    def n_places(self) -> int: ...

    def scores(self, descriptors: np.ndarray, exclude: int | None = None) -> np.ndarray:
        """(n_places,) vote score of every place for query ``descriptors`` (n, d) float32."""
        ...

    def shortlist(self, descriptors: np.ndarray, k: int, exclude: int | None = None) -> np.ndarray:
        """Indices of the ``k`` best-voted places, best first; ``exclude`` left out."""
        ...


@dataclass(frozen=True)
class CompactParams:
    """IVF-PQ and voting settings of a :class:`CompactPlaceIndex`.

    ``lists``: inverted lists of the coarse quantiser (None: from the training sample, see
    :func:`lists_for`); ``subquantizers`` x ``bits``: the bits per code (32 x 4 here: a SIFT
    descriptor in 16 bytes). ``bits=4`` is faiss's fast-scan PQ (``IndexIVFPQFastScan``), whose
    lists are scanned with SIMD lookups in registers; ``bits=8`` the plain IVF-PQ of table
    lookups (``PQ16x8``: the same 16 bytes; ``docs/speed.md`` has both measured); ``probes``:
    lists searched per query descriptor (8: at 10,000 places of 8-bit codes,
    ``bench_big_maps.py --probes`` 194 ms a query against 355 ms with 16, the same top-1, 95 %
    of the shortlist the same; 4: 113 ms, 89 %); ``neighbours`` and
    ``max_distance_ratio`` as :class:`IndexParams`' (on the codes' approximate distances);
    ``train_per_list``: training descriptors per list (faiss's k-means wants at least 39);
    ``threads``: Python threads a query's search is split over (:meth:`CompactPlaceIndex.search`;
    training and adding run on one).
    """

    lists: int | None = None
    subquantizers: int = 32
    bits: int = 4
    probes: int = 8
    neighbours: int = 8
    max_distance_ratio: float = 1.25
    train_per_list: int = 40
    threads: int = 2

    def __post_init__(self) -> None:
        values = (self.subquantizers, self.probes, self.neighbours, self.train_per_list)
        if min(values) < 1 or self.threads < 1 or (self.lists is not None and self.lists < 1):
            raise ValueError(f"lists, subquantizers, probes, neighbours, train_per_list and "
                             f"threads must be >= 1, got {self}")  # fmt: skip
        if not self.max_distance_ratio >= 1:
            raise ValueError(f"max_distance_ratio must be >= 1, got {self.max_distance_ratio!r}")
        if self.bits not in (4, 8):
            raise ValueError(f"bits must be 4 (fast scan) or 8, got {self.bits!r}")

    @property
    def factory(self) -> str:
        """The faiss ``index_factory`` string of these settings (``lists`` must be set)."""
        codes = f"PQ{self.subquantizers}x4fs" if self.bits == 4 else f"PQ{self.subquantizers}x8"
        return f"IVF{self.lists}_HNSW32,{codes}"


MAX_LISTS = 4096
MIN_LISTS = 16
MIN_TRAINING = 1000
"""The smallest training sample (the codebooks' k-means has 256 centroids per sub-space)."""


def lists_for(n_descriptors: int) -> int:
    """Inverted lists for a map of ``n_descriptors``: the power of two nearest
    ``2 * sqrt(n)``, from 16 to 4,096 (about 4,096 at 10,000 places of 1,000 keypoints, a few
    thousand codes per list)."""
    target = 2.0 * np.sqrt(max(n_descriptors, 1))
    return int(np.clip(2 ** round(np.log2(target)), MIN_LISTS, MAX_LISTS))


class CompactPlaceIndex:
    """Product-quantised codes of every map descriptor in inverted lists, voting for places.

    Ids are place indices (the order places were added in); ``keypoint_counts`` (m,) the
    keypoints each place has (for :func:`place_weights`).
    """

    def __init__(self, index: faiss.Index, keypoint_counts: np.ndarray, params: CompactParams):
        self._index = index
        self._ivf = faiss.extract_index_ivf(index)
        self._ivf.nprobe = params.probes
        self._counts = list(np.asarray(keypoint_counts, dtype=np.int64))
        self._weights: np.ndarray | None = None
        self.params = params

    @classmethod
    def train(
        cls,
        sample: np.ndarray,
        params: CompactParams | None = None,
        n_descriptors: int | None = None,
    ) -> CompactPlaceIndex:
        """An empty index whose quantisers are trained on ``sample`` (n, d) float32 descriptors,
        a spread of the map's ``n_descriptors`` (default: the sample's size;
        :func:`training_size` says how many to take). Without ``params.lists``, the lists are
        :func:`lists_for` the map, at most one per ``train_per_list`` of the sample.
        ``ValueError`` for a sample of fewer than :data:`MIN_TRAINING` descriptors."""
        params = params or CompactParams()
        sample = np.ascontiguousarray(sample, dtype=np.float32)
        if sample.ndim != 2 or len(sample) < MIN_TRAINING:
            raise ValueError(
                f"a training sample needs (n >= {MIN_TRAINING}, d) descriptors, got {sample.shape}"
            )
        if sample.shape[1] % params.subquantizers:
            raise ValueError(f"{params.subquantizers} subquantizers do not divide descriptors "
                             f"of {sample.shape[1]} values")  # fmt: skip
        if params.lists is None:
            most = max(MIN_LISTS, len(sample) // params.train_per_list)
            params = replace(params, lists=min(lists_for(n_descriptors or len(sample)), most))
        faiss.omp_set_num_threads(1)  # see :meth:`search`
        index = faiss.index_factory(sample.shape[1], params.factory)
        # Polysemous training (codes ordered for Hamming filtering, which voting does not use)
        # took 30 times as long as the rest: 87 s for 3,000 descriptors here.
        ivf_pq: Any = faiss.downcast_index(faiss.extract_index_ivf(index))
        if hasattr(ivf_pq, "do_polysemous_training"):
            ivf_pq.do_polysemous_training = False
        index.train(sample)
        return cls(index, np.zeros(0, dtype=np.int64), params)

    @property
    def n_places(self) -> int:
        """Number of places in the index."""
        return len(self._counts)

    @property
    def n_codes(self) -> int:
        """Number of descriptor codes held."""
        return int(self._index.ntotal)

    @property
    def dim(self) -> int:
        """Values per descriptor."""
        return int(self._index.d)

    @property
    def keypoint_counts(self) -> np.ndarray:
        """(m,) int64 keypoints of each place, in place order."""
        return np.array(self._counts, dtype=np.int64)

    def emptied(self) -> CompactPlaceIndex:
        """An index with the same trained quantisers and no place (e.g. to index another map
        of the same kind of descriptors without training again)."""
        empty = faiss.clone_index(self._index)
        empty.reset()
        return CompactPlaceIndex(empty, np.zeros(0, dtype=np.int64), self.params)

    def add_place(self, descriptors: np.ndarray) -> int:
        """Encode a place's descriptors (n, d) and add them as the next place; its index."""
        return self.add_places([descriptors])[0]

    def add_places(self, places: list[np.ndarray]) -> list[int]:
        """Encode several places' descriptors at once (one faiss call); their indices."""
        first = self.n_places
        counts = [len(d) for d in places]
        rows = [np.asarray(d, dtype=np.float32).reshape(-1, self.dim) for d in places]
        stacked = np.ascontiguousarray(np.concatenate(rows) if rows else np.zeros((0, self.dim)))
        ids = np.repeat(np.arange(first, first + len(places), dtype=np.int64), counts)
        if len(stacked):
            faiss.omp_set_num_threads(1)
            self._index.add_with_ids(stacked.astype(np.float32), ids)
        self._counts += counts
        self._weights = None
        return list(range(first, first + len(places)))

    def scores(self, descriptors: np.ndarray, exclude: int | None = None) -> np.ndarray:
        """(n_places,) vote score of every place for query ``descriptors`` (n, d) float32, as
        :meth:`PlaceIndex.scores` (``exclude``: a place index left out)."""
        descriptors = np.ascontiguousarray(descriptors, dtype=np.float32)
        if self.n_codes == 0 or len(descriptors) == 0:
            return np.zeros(self.n_places)
        check_query(descriptors, self.dim)
        k = min(self.params.neighbours, self.n_codes)
        k_search = min(2 * k if exclude is not None else k, self.n_codes)
        dist_sq, place_of = self.search(descriptors, k_search)
        if self._weights is None:
            self._weights = place_weights(np.array(self._counts))
        return vote(place_of, dist_sq, self._weights, self.params.max_distance_ratio, k, exclude)

    def search(self, descriptors: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """``(dist_sq, place_of)`` (n, k): approximate squared distances to the ``k`` nearest
        codes of each query row and their places (-1: none). The rows are split over
        ``params.threads`` Python threads, each searching with one OpenMP thread (faiss
        releases the GIL; OpenMP's spinning threads on a shared machine made training 7 times
        slower with two than with one here)."""

        def search(part: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            faiss.omp_set_num_threads(1)
            return self._index.search(part, k)

        threads = min(self.params.threads, len(descriptors))
        if threads <= 1:
            return search(descriptors)
        with ThreadPoolExecutor(threads) as pool:
            found = list(pool.map(search, np.array_split(descriptors, threads)))
        return np.vstack([d for d, _ in found]), np.vstack([p for _, p in found])

    def shortlist(self, descriptors: np.ndarray, k: int, exclude: int | None = None) -> np.ndarray:
        """Indices of the ``k`` best-voted places, best first (see :func:`best_places`)."""
        return best_places(self.scores(descriptors, exclude), k, exclude)

    def to_bytes(self) -> np.ndarray:
        """The trained quantisers and every code, as a uint8 array (:meth:`from_bytes`)."""
        return faiss.serialize_index(self._index)

    @classmethod
    def from_bytes(
        cls, data: np.ndarray, keypoint_counts: np.ndarray, params: CompactParams | None = None
    ) -> CompactPlaceIndex:
        """The index :meth:`to_bytes` gave, for places with ``keypoint_counts``; ``ValueError``
        if ``data`` is no such index or holds another number of codes."""
        try:
            index = faiss.deserialize_index(np.ascontiguousarray(data, dtype=np.uint8))
            faiss.extract_index_ivf(index)
        except RuntimeError as error:
            first = str(error).strip().splitlines()[0] if str(error).strip() else "unreadable"
            raise ValueError(f"not a compact place index: {first}") from None
        counts = np.asarray(keypoint_counts, dtype=np.int64)
        if int(index.ntotal) != int(counts.sum()):
            raise ValueError(
                f"compact place index holds {index.ntotal} codes, its places {counts.sum()}"
            )
        ivf: Any = faiss.downcast_index(faiss.extract_index_ivf(index))
        layout = {
            "lists": int(ivf.nlist),
            "subquantizers": int(ivf.pq.M),
            "bits": int(ivf.pq.nbits),
        }
        return cls(index, counts, replace(params or CompactParams(), **layout))


def training_size(n_descriptors: int, params: CompactParams | None = None) -> int:
    """How many descriptors to train a :class:`CompactPlaceIndex` for a map of
    ``n_descriptors`` on: ``train_per_list`` per list, at most the map's."""
    params = params or CompactParams()
    lists = params.lists or lists_for(n_descriptors)
    return min(n_descriptors, lists * params.train_per_list)
