"""Descriptor matching of a query against its shortlisted places: the product's exact brute
force against two approximations, on time and on the evidence each keeps.

    python benchmarks/bench_matching.py MAP_DB QUERIES [--queries 12] [--checks 16,32]

For each query (read and extracted as ``Localizer.extract`` does), the retrieval index's
shortlist (``EvidenceParams.shortlist`` places; the map must have an index, 32+ places) is
matched, on one OpenCV thread, by:

* ``exact``: :func:`localizer.matching.match_descriptors` (brute-force 2-NN, the product);
* ``flann-C``: a kd-tree per place (4 trees, built once, as a loaded map would keep them), 2-NN
  with ``C`` leaf checks, then the same ratio test (:func:`localizer.matching.ratio_test_pairs`);
* ``voted``: only the query rows whose retrieval neighbours (the index's ``neighbours`` nearest
  map descriptors) include a descriptor of the place, matched exactly.

Each set of pairs is verified as the product does (:func:`localizer.verification.verify`, the
map's calibrated motion). Printed per method: median matching time per place, its speed-up over
``exact``, the pairs, and the inliers summed over the places of the query's own room and of the
other rooms, each as a share of ``exact``'s. Queries are spread evenly over QUERIES (a dataset
folder), capture points (``*_000``) left out.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import cv2
import numpy as np

from localizer.localizer import Localizer, LocalizerConfig
from localizer.matching import DEFAULT_RATIO, match_descriptors, ratio_test_pairs
from localizer.panorama_io import read_panorama
from localizer.verification import verify
from mapdb.dataset import read_dataset
from toploc.maps import load_map

FLANN_INDEX_KDTREE = 1
Matcher = Callable[[np.ndarray, int], np.ndarray]  # (query descriptors, place index) -> pairs


def flann_matcher(table_descriptors: Sequence[np.ndarray], checks: int) -> Matcher:
    """2-NN in a kd-forest per place (built here, once), then the product's ratio test."""
    forests = [
        (cv2.flann.Index(d, {"algorithm": FLANN_INDEX_KDTREE, "trees": 4}), d)
        for d in table_descriptors
    ]

    def match(query: np.ndarray, place: int) -> np.ndarray:
        forest, reference = forests[place]
        if len(reference) < 2 or len(query) == 0:
            return np.zeros((0, 2), np.int64)
        nearest, dist_sq = forest.knnSearch(query, 2, params={"checks": checks})
        distances = np.sqrt(np.maximum(dist_sq.astype(np.float64), 0.0))
        return ratio_test_pairs(nearest.astype(np.int64), distances, DEFAULT_RATIO)

    return match


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("map_db", type=Path)
    parser.add_argument("queries", type=Path)
    parser.add_argument("--queries", dest="n_queries", type=int, default=12)
    parser.add_argument("--checks", default="16,32", help="FLANN leaf checks to try")
    args = parser.parse_args(argv)
    cv2.setNumThreads(1)
    print(f"load: {os.getloadavg()}")

    loaded = load_map(args.map_db)
    if loaded.index is None:
        raise SystemExit(f"{args.map_db} has {len(loaded.places)} places: no retrieval index")
    localizer = Localizer(loaded, LocalizerConfig())
    table, index = loaded.table, loaded.index
    params = localizer.evidence_params.verification()
    per_place = [np.ascontiguousarray(table.descriptors[table.rows(i)], np.float32)
                 for i in range(len(table.place_ids))]  # fmt: skip
    methods: dict[str, Matcher] = {"exact": lambda q, i: match_descriptors(q, per_place[i])}
    for checks in (int(c) for c in args.checks.split(",") if c):
        methods[f"flann-{checks}"] = flann_matcher(per_place, checks)
    voted_rows: dict[int, np.ndarray] = {}

    def voted(query: np.ndarray, place: int) -> np.ndarray:
        rows = voted_rows[place]
        pairs = match_descriptors(query[rows], per_place[place])
        pairs[:, 0] = rows[pairs[:, 0]]
        return pairs

    methods["voted"] = voted

    pool = [e for e in read_dataset(args.queries) if not Path(e.image).stem.endswith("_000")]
    picked = np.unique(np.round(np.linspace(0, len(pool) - 1, args.n_queries)).astype(int))
    times = {name: [] for name in methods}
    totals = {name: np.zeros(3) for name in methods}  # pairs, own-room inliers, other inliers
    for entry in (pool[i] for i in picked):
        fingerprint = localizer.extract(read_panorama(entry.path))
        query = np.ascontiguousarray(fingerprint.descriptors, np.float32)
        query_rays = fingerprint.rays()
        shortlist = index.shortlist(query, localizer.evidence_params.shortlist)
        neighbours, _ = index.search(query, index.params.neighbours)
        place_of = table.keypoint_place_index[np.maximum(neighbours, 0)]
        for place in (int(p) for p in shortlist):
            voted_rows[place] = np.flatnonzero((place_of == place).any(axis=1))
            place_rays = table.fingerprint(place).rays()
            own = table.rooms[place] == entry.room
            for name, match in methods.items():
                t0 = time.perf_counter()
                pairs = match(query, place)
                times[name].append((time.perf_counter() - t0) * 1e3)
                inliers = (
                    verify(query_rays, place_rays, pairs, params).inliers
                    if len(pairs) >= localizer.evidence_params.min_matches
                    else 0
                )
                totals[name] += (len(pairs), inliers if own else 0, 0 if own else inliers)

    exact_ms, exact = statistics.median(times["exact"]), totals["exact"]
    print(f"\n{len(picked)} queries x {len(times['exact']) // len(picked)} shortlisted places, "
          f"{args.map_db.name}, one OpenCV thread\n")  # fmt: skip
    print("| method | ms per place | speed-up | pairs | own-room inliers | other-room inliers |")
    print("|---|---|---|---|---|---|")
    for name in methods:
        ms, (pairs, own, other) = statistics.median(times[name]), totals[name]
        print(
            f"| {name} | {ms:.2f} | {exact_ms / ms:.1f}x | {pairs / exact[0]:.0%} "
            f"| {own / max(exact[1], 1):.0%} ({own:.0f}) | {other / max(exact[2], 1):.0%} "
            f"({other:.0f}) |"
        )
    print(f"\nload: {os.getloadavg()}")


if __name__ == "__main__":
    main()
