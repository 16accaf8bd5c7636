"""Benchmark the map database: build time per panorama, size per place, start-up load time.

1. Renders ``--n-panoramas`` synthetic cylindrical panoramas (random shapes, blurred, seeded) and
   builds a map from them with the real extractor (``toploc map build``'s pipeline), timing the
   build per panorama with ``--workers`` processes.
2. Reports the database size per place (after a WAL checkpoint).
3. Makes a ``--n-places`` map by re-inserting those fingerprints under new image hashes, then
   times loading every fingerprint: as per-row Fingerprints, and stacked per detector.

    python benchmarks/bench_mapdb.py [--n-panoramas 24] [--n-places 1000] [--workers 2]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from mapdb.build import Status, build_map
from mapdb.database import MapDatabase
from mapdb.dataset import read_manifest
from mapdb.loading import load_fingerprint_table, load_fingerprints
from mapdb.records import Fingerprint, NewPlace
from toploc.commands.map import parse_detectors
from toploc.extraction import resolve_extractor


def render_panorama(seed: int, width_px: int, height_px: int) -> np.ndarray:
    """A grey panorama of random rectangles and discs on a gradient, blurred (deterministic)."""
    rng = np.random.default_rng(seed)
    image = np.tile(np.linspace(60, 180, width_px, dtype=np.float32), (height_px, 1))
    for _ in range(width_px // 8):
        x, y = int(rng.integers(0, width_px)), int(rng.integers(0, height_px))
        size = int(rng.integers(3, height_px // 3))
        shade = float(rng.integers(0, 256))
        if rng.random() < 0.5:
            cv2.rectangle(image, (x, y), (x + size, y + size // 2), shade, -1)
        else:
            cv2.circle(image, (x, y), size // 2, shade, -1)
    image = cv2.GaussianBlur(image, (0, 0), 1.2) + rng.normal(0, 3, image.shape)
    return np.clip(image, 0, 255).astype(np.uint8)


def write_dataset(folder: Path, n: int, width_px: int, height_px: int) -> Path:
    """``n`` rendered panoramas in ``folder`` with a manifest over three rooms."""
    folder.mkdir(parents=True, exist_ok=True)
    lines = ["image,room,x_m,y_m,heading_deg"]
    for i in range(n):
        cv2.imwrite(str(folder / f"pano_{i:04d}.png"), render_panorama(i, width_px, height_px))
        lines.append(f"pano_{i:04d}.png,room{i % 3},{i * 0.5},0,0")
    (folder / "manifest.csv").write_text("\n".join(lines) + "\n")
    return folder


def checkpointed_size_bytes(path: Path) -> int:
    """File size after folding the write-ahead log into the database."""
    with MapDatabase.open(path) as map_db:
        map_db.db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    return path.stat().st_size


def make_large_map(path: Path, source: MapDatabase, n_places: int) -> float:
    """Fill ``path`` with ``n_places`` places cycling the fingerprints of ``source``; seconds."""
    by_place: dict[int, list[Fingerprint]] = {}
    for stored in load_fingerprints(source):
        by_place.setdefault(stored.place_id, []).append(stored.fingerprint)
    templates = list(by_place.values())
    start = time.perf_counter()
    with MapDatabase.open(path) as map_db:
        for i in range(n_places):
            place = NewPlace(f"room{i % 20}", f"{i:064x}", f"bench/{i}", x_m=0.0, y_m=0.0)
            map_db.add_place(place, templates[i % len(templates)])
    return time.perf_counter() - start


def best_of(repeats: int, function: Callable[[], object]) -> float:
    """Fastest wall time of ``repeats`` calls, seconds."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-panoramas", type=int, default=24)
    parser.add_argument("--width-px", type=int, default=720)
    parser.add_argument("--height-px", type=int, default=120)
    parser.add_argument("--detector", default="sift,mser")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--n-places", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        tmp_dir = Path(tmp)
        dataset = write_dataset(
            tmp_dir / "dataset", args.n_panoramas, args.width_px, args.height_px
        )
        extract = resolve_extractor(parse_detectors(args.detector))
        small_db = tmp_dir / "small.db"
        with MapDatabase.open(small_db) as map_db:
            start = time.perf_counter()
            report = build_map(
                map_db, read_manifest(dataset), extract, workers=args.workers, progress=False
            )
            build_s = time.perf_counter() - start
            counts = {d: 0 for d in args.detector.split(",")}
            for stored in load_fingerprints(map_db):
                counts[stored.fingerprint.detector] += stored.fingerprint.n
            insert_s = make_large_map(tmp_dir / "large.db", map_db, args.n_places)
        n_built = report.count(Status.ADDED)
        small_size = checkpointed_size_bytes(small_db)
        large_size = checkpointed_size_bytes(tmp_dir / "large.db")

        with MapDatabase.open(tmp_dir / "large.db", readonly=True) as large:
            rows_s = best_of(args.repeats, lambda: load_fingerprints(large))
            detectors = list(counts)
            table_s = best_of(
                args.repeats, lambda: [load_fingerprint_table(large, d) for d in detectors]
            )
            n_rows = len(load_fingerprints(large))

    mean_kp = ", ".join(f"{d} {n / max(n_built, 1):.0f}" for d, n in counts.items())
    table = [
        ("panoramas built", f"{n_built} of {args.width_px}x{args.height_px} px ({mean_kp} kp)"),
        (
            "build time / panorama",
            f"{1000 * build_s / max(n_built, 1):.1f} ms ({args.workers} workers, {args.detector})",
        ),
        ("database size / place", f"{small_size / max(n_built, 1) / 1024:.1f} KiB"),
        (
            f"insert {args.n_places} places",
            f"{insert_s:.2f} s ({1000 * insert_s / args.n_places:.2f} ms / place)",
        ),
        (f"{args.n_places}-place map size", f"{large_size / 1e6:.1f} MB"),
        (f"load all ({n_rows} fingerprints)", f"{1000 * rows_s:.0f} ms  load_fingerprints"),
        ("load stacked per detector", f"{1000 * table_s:.0f} ms  load_fingerprint_table"),
    ]
    width = max(len(name) for name, _ in table)
    for name, value in table:
        print(f"{name:<{width}}  {value}")


if __name__ == "__main__":
    main()
