"""Time per query at real 360° camera resolution: 2048 x 1024 equirectangular panoramas against
maps of 30, 100 and 300 places, as a ratio of the query's own feature extraction time.

Data (render first; the photos are 1024 x 512 CC0 panoramas, so 2048-wide renders are upsampled):

    python -m toploc dataset render MAP --world photos --projection equirect --width 2048 \\
        --spacing 2.6
    python -m toploc dataset render QUERIES --world photos --projection equirect --width 2048 \\
        --spacing 3.5 --random-heading --seed 1

Maps are built through the product (``mapdb.build.build_map`` with
``toploc.extraction.resolve_extractor``, two worker processes) into SQLite files under
``--cache-dir``, not calibrated (the likelihood is not part of the timed path). The places are
taken round-robin over the rooms, so each smaller map is a prefix of the larger one and every
room is in every map. Each map is loaded with ``toploc.maps.load_map`` and timed in its own
spawned process (so its peak RSS, ``VmHWM``, is its own): per query the wall time of
``Localizer.observe(image)`` (grey 2048 x 1024 in memory; reading the PNG is not timed) and its
``timing_ms`` (extraction, retrieval, verification). Queries are taken evenly from QUERIES,
leaving out the capture points (those coincide with map places). One warm-up query is not counted.

Widths: ``1024`` is the product's default (an equirect image is shrunk to ``max_width_px`` 1024
before SIFT, ``localizer.features.CAMERA_DEFAULTS``); ``2048`` is full resolution, map and
queries both: the map is built with ``max_width_px=2048`` (``toploc map build --read-width
2048``), and the localizer reads its queries as the map's places were read.

Extraction on both cores: the localizer detects a query's two halves (with the wrap margin of
overlap) on two threads (``LocalizerConfig.extraction_threads = 2``); retrieval, matching and
verification also use both (``IndexParams.threads``, ``EvidenceParams.threads``). The same
queries are extracted as one call with OpenCV's default thread count (``cv2.getNumThreads()``),
as one call with ``cv2.setNumThreads(1)``, and as the product's two halves; and the map of
``--one-thread-size`` places is also timed with one-call extraction (``extraction_threads=1``),
so the ratio can be read against both.

    python benchmarks/bench_real_resolution.py MAP QUERIES [--sizes 30,100,300] [--queries 20]
        [--widths 1024,2048] [--full-sizes 30,100,300] [--one-thread-size 100]
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import shutil
import statistics
import tempfile
import time
from collections.abc import Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from process_memory import rss_mib
from scipy.spatial import cKDTree

from localizer.cameras import CameraSpec
from localizer.features import extract_with_camera
from localizer.localizer import Localizer, LocalizerConfig
from localizer.panorama_io import read_panorama
from mapdb.build import Extractor, build_map
from mapdb.database import MapDatabase
from mapdb.dataset import ManifestEntry, read_manifest
from mapdb.records import Fingerprint
from toploc.extraction import resolve_extractor
from toploc.maps import load_map

DEFAULT_WIDTH = 1024  # CAMERA_DEFAULTS["equirect"]["max_width_px"]


# --- extraction threads -----------------------------------------------------------------------


@contextmanager
def cv2_threads(n: int) -> Iterator[None]:
    """OpenCV's thread count set to ``n`` inside the block (it is process-wide), then restored."""
    before = cv2.getNumThreads()
    cv2.setNumThreads(n)
    try:
        yield
    finally:
        cv2.setNumThreads(before)


def recovered(product: Fingerprint, other: Fingerprint) -> float:
    """Share of the product's keypoints that ``other`` has within 0.5 px."""
    if not product.n or not other.n:
        return float("nan")
    distance, _ = cKDTree(other.keypoints_xy).query(product.keypoints_xy)
    return float(np.mean(distance < 0.5))


# --- localizers at a chosen width ------------------------------------------------------------


# --- maps and queries ------------------------------------------------------------------------


def round_robin(entries: Sequence[ManifestEntry]) -> list[ManifestEntry]:
    """The entries interleaved over the rooms (each room's places in a spread order), so every
    prefix covers the rooms evenly."""
    by_room: dict[str, list[ManifestEntry]] = {}
    for entry in entries:
        by_room.setdefault(entry.room, []).append(entry)
    queues = [
        [places[i] for i in np.argsort((np.arange(len(places)) * 0.618034) % 1.0)]
        for _, places in sorted(by_room.items())
    ]
    order: list[ManifestEntry] = []
    while any(queues):
        order += [queue.pop(0) for queue in queues if queue]
    return order


def build_maps(
    entries: Sequence[ManifestEntry], sizes: Sequence[int], width: int, cache: Path
) -> dict[int, Path]:
    """SQLite maps of the first ``size`` entries, each grown from the previous one's copy."""
    overrides = {} if width == DEFAULT_WIDTH else {"max_width_px": width}  # --read-width
    extractor: Extractor = resolve_extractor(("sift",), overrides=overrides)
    paths, previous = {}, None
    for size in sorted(sizes):
        path = cache / f"map_w{width}_{size}.db"
        if previous is not None and not path.exists():
            shutil.copyfile(previous, path)
        t0 = time.perf_counter()
        with MapDatabase.open(path) as map_db:
            report = build_map(map_db, entries[:size], extractor, workers=2, progress=False)
        added = report.summary()
        print(f"  map w{width} {size}: {added} ({time.perf_counter() - t0:.0f} s)", flush=True)
        paths[size], previous = path, path
    return paths


def pick_queries(entries: Sequence[ManifestEntry], n: int) -> list[ManifestEntry]:
    """``n`` entries evenly spread, capture points (``*_000``) left out."""
    pool = [e for e in entries if not Path(e.image).stem.endswith("_000")]
    pick = np.unique(np.round(np.linspace(0, len(pool) - 1, n)).astype(int))
    return [pool[i] for i in pick]


# --- timing (in a child process per map) -----------------------------------------------------


@dataclass
class RunResult:
    label: str
    places: int
    keypoints: int
    width: int
    total_ms: list[float]
    stage_ms: dict[str, list[float]]
    right: int
    load_rss_mib: float
    peak_rss_mib: float


def time_map(
    db: Path, queries: Sequence[tuple[str, str]], width: int, label: str, threads: int
) -> RunResult:
    """Load the map at ``db`` and time ``observe`` on every query (path, room); the first twice."""
    loaded = load_map(db)
    localizer = Localizer(loaded, LocalizerConfig(extraction_threads=threads))
    load_rss = rss_mib()
    images = [(read_panorama(path), room) for path, room in queries]
    localizer.observe(images[0][0])  # warm-up
    totals, stages, right = [], {"extraction": [], "retrieval": [], "verification": []}, 0
    for image, room in images:
        t0 = time.perf_counter()
        observation = localizer.observe(image)
        totals.append((time.perf_counter() - t0) * 1e3)
        for stage, values in stages.items():
            values.append(observation.timing_ms[stage])
        best = observation.evidence.best
        right += int(best is not None and best.inliers > 0 and best.room == room)
    return RunResult(
        label, len(loaded.places), int(loaded.table.keypoint_counts.sum()), width, totals,
        stages, right,
        load_rss, rss_mib("VmHWM"),
    )  # fmt: skip


def in_child(*args: Any) -> RunResult:
    """:func:`time_map` in a fresh spawned process (so its peak memory is the map's own)."""
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(1, mp_context=context) as pool:
        return pool.submit(time_map, *args).result()


def time_extraction(paths: Sequence[str], widths: Sequence[int]) -> list[str]:
    """Rows of the extraction table: one call (OpenCV's default threads, and one OpenCV
    thread) and the product's two halves on two threads."""
    rows = []
    for width in widths:
        over = {} if width == DEFAULT_WIDTH else {"max_width_px": width}
        times: dict[str, list[float]] = {"default": [], "one": [], "halves": []}
        share, counts = [], []
        for path in paths:
            image = read_panorama(path)
            for name in times:  # interleaved, so background load hits all three alike
                t0 = time.perf_counter()
                if name == "default":
                    whole = extract_with_camera(image, CameraSpec(), "sift", **over)
                elif name == "one":
                    with cv2_threads(1):
                        extract_with_camera(image, CameraSpec(), "sift", **over)
                else:
                    halves = extract_with_camera(image, CameraSpec(), "sift", threads=2, **over)
                times[name].append((time.perf_counter() - t0) * 1e3)
            share.append(recovered(whole, halves))
            counts.append((whole.n, halves.n))
        med = {k: statistics.median(v) for k, v in times.items()}
        rows.append(
            f"| {width} | {med['default']:.0f} | {med['one']:.0f} | {med['halves']:.0f} "
            f"| {med['one'] / med['default']:.2f}x | {med['default'] / med['halves']:.2f}x "
            f"| {np.mean([c[0] for c in counts]):.0f} / {np.mean([c[1] for c in counts]):.0f} "
            f"| {100 * np.nanmean(share):.1f} % |"
        )
    return rows


def pct(values: Sequence[float], q: float) -> float:
    return float(np.percentile(values, q))


def result_row(r: RunResult) -> str:
    ext = r.stage_ms["extraction"]
    ratio = [t / e for t, e in zip(r.total_ms, ext, strict=True)]
    med = {k: statistics.median(v) for k, v in r.stage_ms.items()}
    return (
        f"| {r.places} | {r.label} | {r.keypoints} | {med['extraction']:.0f} "
        f"| {pct(r.total_ms, 50):.0f} | {pct(r.total_ms, 95):.0f} "
        f"| {pct(ratio, 50):.2f}x | {pct(ratio, 95):.2f}x "
        f"| {med['retrieval']:.0f} | {med['verification']:.0f} | {r.right}/{len(r.total_ms)} "
        f"| {r.load_rss_mib:.0f} | {r.peak_rss_mib:.0f} |"
    )


def main(argv: Sequence[str] | None = None) -> list[RunResult]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("map_dataset", type=Path)
    parser.add_argument("query_dataset", type=Path)
    parser.add_argument("--sizes", default="30,100,300")
    parser.add_argument("--widths", default="1024,2048", help="1024: the product default")
    parser.add_argument("--full-sizes", default="30,100,300", help="map sizes timed at 2048")
    parser.add_argument("--queries", type=int, default=20)
    parser.add_argument("--extraction-images", type=int, default=0, help="0: every query")
    parser.add_argument(
        "--one-thread-size", type=int, default=100, help="0: no one-thread extraction row"
    )
    parser.add_argument(
        "--cache-dir", type=Path, default=Path(tempfile.gettempdir()) / "toploc-bench-realres"
    )
    args = parser.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",")]
    widths = [int(w) for w in args.widths.split(",")]
    full_sizes = {int(s) for s in args.full_sizes.split(",") if s}
    args.cache_dir.mkdir(parents=True, exist_ok=True)
    print(f"load before: {os.getloadavg()}; cv2.getNumThreads() = {cv2.getNumThreads()}")

    entries = round_robin(read_manifest(args.map_dataset))
    if len(entries) < max(sizes):
        raise SystemExit(f"{args.map_dataset} has {len(entries)} places, {max(sizes)} asked")
    picked = pick_queries(read_manifest(args.query_dataset), args.queries)
    queries = [(str(q.path), q.room) for q in picked]
    print("\nextraction (median ms per query, interleaved):", flush=True)
    extraction_rows = time_extraction(
        [p for p, _ in queries[: args.extraction_images or None]], widths
    )

    results = []
    for width in widths:
        timed = [s for s in sizes if width == DEFAULT_WIDTH or s in full_sizes]
        maps = build_maps(entries, timed, width, args.cache_dir)
        for size, db in maps.items():
            print(f"  timing {size} places at {width} ...", flush=True)
            results.append(in_child(db, queries, width, f"{width}", 2))
            if size == args.one_thread_size:
                results.append(in_child(db, queries, width, f"{width}, 1 extraction thread", 1))

    print(f"\nload after: {os.getloadavg()}")
    print(
        f"\n{len(queries)} queries (2048 x 1024 equirect, photos world), median / p95 per query\n"
    )
    print(
        "| places | read at (px wide) | map keypoints | extraction ms | total ms | total p95 ms "
        "| total / extraction | p95 of ratio | retrieval ms | verification ms | top-1 room "
        "| RSS loaded MiB | peak RSS MiB |"
    )
    print("|" + "---|" * 13)
    print("\n".join(result_row(r) for r in results))
    n_extracted = min(args.extraction_images or len(queries), len(queries))
    print(
        f"\nSIFT extraction of {n_extracted} queries, median ms (one call with OpenCV's "
        "default threads, one call with 1 thread, the product's two halves on 2 threads)\n"
    )
    print(
        "| read at | one call | one call, 1 thread | halves, 2 threads | 1 thread / one call "
        "| halves speed-up vs one call | keypoints one call / halves | one call's found |"
    )
    print("|" + "---|" * 8)
    print("\n".join(extraction_rows))
    return results


if __name__ == "__main__":
    main()
