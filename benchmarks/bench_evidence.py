"""How well place evidence separates the right room from the others, per extraction variant.

For a dataset (a map's panoramas) and optionally a second one (queries taken elsewhere in the
same rooms), every variant extracts all panoramas in memory, then each query (each map place
left out in turn when no query dataset is given) is matched against the map as the localizer
does (ratio test, essential matrix on rays, inliers). Per query we keep the best count
(``--count``: ``spread``, the inliers weighted by the share of the horizon they cover, which
the likelihood reads; or the raw ``inliers``) of its own room and of every other room, and
print:

- own room: median and quartiles of the own room's best count;
- best other: the same for the best count among the other rooms, look-alike rooms included;
- first: how often the own room's count is the highest (ties count against);
- margin 2x: how often it is at least twice the best other room's and at least 10;
- AUC: the probability that a same-room count beats a random other-room count.

Run: ``python benchmarks/bench_evidence.py DATASET [--queries DATASET] [--variants a,b]
[--count spread|inliers]``.
Variants are named in ``VARIANTS`` below (extraction overrides and evidence parameters).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from localizer.cameras import CameraSpec
from localizer.evidence import EvidenceParams, place_evidence
from localizer.features import extract_with_camera
from localizer.likelihood import COUNTS, room_inliers
from localizer.loaded_map import LoadedMap
from localizer.panorama_io import read_panorama
from mapdb.dataset import read_manifest
from mapdb.records import Fingerprint, FingerprintTable, MapSnapshot, Place

VARIANTS: dict[str, tuple[dict[str, Any], dict[str, Any]]] = {
    "base": ({}, {}),
    "contrast02": ({"sift_contrast_threshold": 0.02}, {}),
    "contrast01": ({"sift_contrast_threshold": 0.01}, {}),
    "upright": ({"upright": True}, {}),
    "rootsift": ({"descriptor": "rootsift"}, {}),
    "upright-root": ({"upright": True, "descriptor": "rootsift"}, {}),
    "up-root-c02": (
        {"upright": True, "descriptor": "rootsift", "sift_contrast_threshold": 0.02},
        {},
    ),
    "min6": ({}, {"min_matches": 6}),
    "ratio09": ({}, {"ratio": 0.9}),
    "width2048": ({"max_width_px": 2048}, {}),
    "planar": ({}, {"motion": "planar"}),
    "planar-min6": ({}, {"motion": "planar", "min_matches": 6}),
    "planar-c02": ({"sift_contrast_threshold": 0.02}, {"motion": "planar"}),
    "planar-up-root": ({"upright": True, "descriptor": "rootsift"}, {"motion": "planar"}),
}


def extract_all(paths: list[Path], overrides: dict[str, Any]) -> list[Fingerprint]:
    return [extract_with_camera(read_panorama(p), CameraSpec(), "sift", **overrides) for p in paths]


def loaded_map(fingerprints: list[Fingerprint], rooms: list[str]) -> LoadedMap:
    ids = list(range(1, len(fingerprints) + 1))
    table = FingerprintTable.stack("sift", ids, rooms, fingerprints)
    places = tuple(Place(i, r) for i, r in zip(ids, rooms, strict=True))
    names = tuple(dict.fromkeys(sorted(rooms)))
    return LoadedMap.from_snapshot(MapSnapshot(Path("memory"), table, places, names, ()))


def counts(
    loaded: LoadedMap,
    queries: list[tuple[Fingerprint, str, int | None]],
    params: EvidenceParams,
    count: str,
) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """Own-room best, best other room, and every other room's best ``count``, per query."""
    own, best_other, others = [], [], []
    for fingerprint, room, exclude in queries:
        evidence = place_evidence(fingerprint, loaded.table, params, loaded.index, exclude)
        best = room_inliers(evidence.places, loaded.rooms, count=count)
        per_room = dict(zip(loaded.rooms, best, strict=True))
        rest = [v for r, v in per_room.items() if r != room]
        own.append(per_room.get(room, 0.0))
        best_other.append(max(rest, default=0.0))
        others += rest
    return np.array(own), np.array(best_other), others


def auc(same: np.ndarray, other: np.ndarray) -> float:
    """P(same > other) + P(same == other) / 2 over all pairs."""
    s, o = np.asarray(same)[:, None], np.asarray(other)[None, :]
    return float(np.mean((s > o) + 0.5 * (s == o)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", type=Path)
    parser.add_argument("--queries", type=Path, default=None)
    parser.add_argument("--variants", default=",".join(VARIANTS))
    parser.add_argument("--count", choices=COUNTS, default="spread")
    args = parser.parse_args()
    entries = read_manifest(args.dataset)
    query_entries = read_manifest(args.queries) if args.queries else []
    print(
        f"map {args.dataset} ({len(entries)} places); queries: "
        + (f"{args.queries} ({len(query_entries)})" if args.queries else "each place left out")
        + f"; count: {args.count}"
    )
    header = f"{'variant':14s} {'own room (q1 med q3)':>22s} {'best other':>18s}"
    print(header + f" {'first':>6s} {'margin2x':>8s} {'AUC':>5s} {'s':>5s}")
    for name in args.variants.split(","):
        extraction, evidence = VARIANTS[name]
        t0 = time.perf_counter()
        map_fps = extract_all([e.path for e in entries], extraction)
        rooms = [e.room for e in entries]
        loaded = loaded_map(map_fps, rooms)
        if query_entries:
            q_fps = extract_all([e.path for e in query_entries], extraction)
            queries = [(fp, e.room, None) for fp, e in zip(q_fps, query_entries, strict=True)]
        else:
            queries = [(fp, r, i + 1) for i, (fp, r) in enumerate(zip(map_fps, rooms, strict=True))]
        params = replace(EvidenceParams(), **evidence)
        own, best_other, others = counts(loaded, queries, params, args.count)
        quart = lambda a: "{:5.0f} {:5.0f} {:5.0f}".format(*np.percentile(a, [25, 50, 75]))  # noqa: E731
        first = np.mean(own > best_other)
        margin = np.mean((own >= 2 * best_other) & (own >= 10))
        print(
            f"{name:14s} {quart(own):>22s} {quart(best_other):>18s} {first:6.0%} {margin:8.0%} "
            f"{auc(own, np.array(others)):5.2f} {time.perf_counter() - t0:5.0f}"
        )


if __name__ == "__main__":
    main()
