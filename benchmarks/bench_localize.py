"""Benchmark place evidence: brute force vs a FLANN index, on maps of 10, 100 and 1,000 places.

How the maps are made (all panoramas rendered, nothing copied or jittered):

- The *target* building is ``building`` seed 0 (corridor, look-alike office_a/office_b, kitchen,
  seminar, storage), one panorama per capture place (1 m grid, random headings), default light.
- Larger maps add *distractor* places: real rendered panoramas of other worlds (``lab``, and
  ``building``/``corridor`` built from other seeds, so other textures and posters), their rooms
  named ``world#seed/room``. A query whose best place is a distractor counts as wrong.
- A map of ``n`` places takes ``min(n, 103)`` target places (evenly spread) plus distractors.
- Queries: the target building under another condition (``--condition``, default
  ``dim_noisy``) at the places of a 0.7 m grid (not the map's 1 m grid), random headings.

Fingerprints are SIFT (the ``sift`` preset, as ``toploc map build`` uses) on 1024 x 192 px
panoramas; the map fingerprints are cached in a map database under ``--cache-dir``.
For each map size: the index build time, then per query the wall time of brute force and of the
index (shortlist + verification), the top-1 room accuracy of both, how often the brute-force
winner is in the shortlist, and peak memory (``ru_maxrss``; current RSS around the index build).

    python benchmarks/bench_localize.py [--quick] [--sizes 10,100,1000] [--queries 20]
"""

from __future__ import annotations

import argparse
import hashlib
import math
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from process_memory import peak_rss_mib, rss_mib

from localizer.evidence import EvidenceParams, QueryEvidence, place_evidence
from localizer.features import extract_preset
from localizer.retrieval import PlaceIndex
from localizer.robot_protocol import Pose2D
from mapdb.database import MapDatabase
from mapdb.loading import load_fingerprint_table
from mapdb.records import Fingerprint, FingerprintTable, NewPlace
from mapdb.workers import spawn_process_pool
from robot.conditions import get_condition, world_under
from robot.render import PanoramaCamera, render_panorama
from robot.scene import build_scene
from robot.world import capture_places
from robot.worlds import make_world

TARGET = ("building", 0, 1.0)
DISTRACTORS = (
    ("lab", 0, 0.5),
    ("building", 1, 1.0),
    ("building", 2, 1.0),
    ("building", 3, 0.5),
    ("lab", 1, 1.0),
    ("corridor", 1, 0.5),
    ("lab", 2, 0.5),
)
CAMERA = PanoramaCamera(width_px=1024, height_px=192)


@dataclass(frozen=True)
class Shot:
    """One panorama to render: world, seed, room, position (room frame) and heading."""

    world: str
    seed: int
    room: str
    x_m: float
    y_m: float
    heading_deg: float
    condition: str = "default"

    @property
    def label(self) -> str:
        """The room name in the map: plain for the target building, prefixed otherwise."""
        if (self.world, self.seed) == TARGET[:2]:
            return self.room
        return f"{self.world}#{self.seed}/{self.room}"


def shots(world: str, seed: int, spacing_m: float, condition: str = "default") -> list[Shot]:
    """A shot at every capture place of the world's grid, seeded random headings."""
    places = capture_places(make_world(world, seed), spacing_m)
    headings = np.random.default_rng([seed, 7, round(spacing_m * 100)]).uniform(
        -180, 180, len(places)
    )
    return [
        Shot(world, seed, p.room, p.x_m, p.y_m, float(h), condition)
        for p, h in zip(places, headings, strict=True)
    ]


_SCENES: dict[tuple[str, int, str], object] = {}


def render_fingerprint(shot: Shot) -> Fingerprint:
    """Render ``shot`` (scenes cached per process) and extract its SIFT fingerprint."""
    key = (shot.world, shot.seed, shot.condition)
    world = make_world(shot.world, shot.seed)
    condition = get_condition(shot.condition)
    if key not in _SCENES:
        _SCENES[key] = build_scene(world_under(world, condition, shot.seed))
    pose = world.building_pose(
        shot.room, Pose2D(shot.x_m, shot.y_m, math.radians(shot.heading_deg))
    )
    noise_seed = (shot.seed, int(shot.x_m * 1000), int(shot.y_m * 1000), len(shot.room))
    image = render_panorama(_SCENES[key], pose, CAMERA, condition, seed=noise_seed, grey=True)
    return extract_preset(image, "sift")


def render_all(items: Sequence[Shot], workers: int) -> Iterator[Fingerprint]:
    """Fingerprints of ``items`` in order, rendered by ``workers`` processes."""
    if workers <= 1:
        yield from map(render_fingerprint, items)
        return
    with spawn_process_pool(workers) as pool:
        yield from pool.map(render_fingerprint, items, chunksize=8)


def map_shots(n_places: int) -> list[Shot]:
    """Target shots first, then distractor shots, until there are at least ``n_places``."""
    result = shots(*TARGET)
    for source in DISTRACTORS:
        if len(result) >= n_places:
            break
        result += shots(*source)
    if len(result) < n_places:
        raise ValueError(f"only {len(result)} places can be rendered, {n_places} asked")
    return result


def cached_table(cache_dir: Path, n_places: int, workers: int) -> tuple[FingerprintTable, int]:
    """The SIFT table of the first ``>= n_places`` shots, target places first (rendered once
    into a map database under ``cache_dir`` and reused by later runs)."""
    items = map_shots(n_places)
    cache_dir.mkdir(parents=True, exist_ok=True)
    path = cache_dir / f"bench_localize_{CAMERA.width_px}x{CAMERA.height_px}.db"
    with MapDatabase.open(path) as map_db:
        done = {p.source for p in map_db.places()}
        todo = [s for s in items if _source(s) not in done]
        if todo:
            print(f"rendering {len(todo)} map panoramas into {path} ...", flush=True)
        for i, (shot, fp) in enumerate(zip(todo, render_all(todo, workers), strict=True)):
            map_db.add_place(_new_place(shot), [fp])
            if (i + 1) % 100 == 0:
                print(f"  {i + 1}/{len(todo)}", flush=True)
        id_of = {p.source: p.id for p in map_db.places()}
        table = load_fingerprint_table(map_db, "sift")
    position = {int(pid): i for i, pid in enumerate(table.place_ids)}
    order = np.array([position[id_of[_source(s)]] for s in items], dtype=np.int64)
    n_target = sum(1 for s in items if s.label == s.room)
    return table.subset(order), n_target


def _source(shot: Shot) -> str:
    return f"{shot.world}#{shot.seed}/{shot.room}/{shot.x_m:.3f},{shot.y_m:.3f}"


def _new_place(shot: Shot) -> NewPlace:
    return NewPlace(
        room=shot.label,
        image_sha256=hashlib.sha256(_source(shot).encode()).hexdigest(),
        source=_source(shot),
        x_m=shot.x_m,
        y_m=shot.y_m,
        heading_deg=shot.heading_deg,
    )


def choose_places(n_total: int, n_target: int, size: int) -> np.ndarray:
    """``min(size, n_target)`` evenly spread target places, then distractors up to ``size``."""
    k = min(size, n_target)
    target = np.unique(np.round(np.linspace(0, n_target - 1, k)).astype(int))
    return np.concatenate([target, np.arange(n_target, n_target + size - len(target))])


@dataclass
class SizeResult:
    size: int
    keypoints: int
    build_s: float
    index_mib: float
    brute_ms: list[float]
    indexed_ms: list[float]
    retrieval_ms: list[float]
    brute_ok: list[bool]
    indexed_ok: list[bool]
    in_shortlist: list[bool]
    peak_mib: float


def top_room(evidence: QueryEvidence) -> str | None:
    best = evidence.best
    return best.room if best is not None and best.inliers > 0 else None


def run_size(
    table: FingerprintTable,
    queries: Sequence[tuple[Shot, Fingerprint]],
    params: EvidenceParams,
    twins: list[str],
) -> SizeResult:
    """Brute force and indexed evidence for every query against ``table``."""
    before = rss_mib()
    t0 = time.perf_counter()
    index = PlaceIndex.build(table)
    build_s = time.perf_counter() - t0
    result = SizeResult(
        len(table.place_ids), len(table.descriptors), build_s, rss_mib() - before,
        [], [], [], [], [], [], 0.0,
    )  # fmt: skip
    for shot, fp in queries:
        t0 = time.perf_counter()
        brute = place_evidence(fp, table, params)
        t1 = time.perf_counter()
        indexed = place_evidence(fp, table, params, index)
        t2 = time.perf_counter()
        result.brute_ms.append((t1 - t0) * 1e3)
        result.indexed_ms.append((t2 - t1) * 1e3)
        result.retrieval_ms.append(indexed.timing_ms["retrieval"])
        result.brute_ok.append(top_room(brute) == shot.room)
        result.indexed_ok.append(top_room(indexed) == shot.room)
        winner = brute.best.place_id if brute.best else None
        result.in_shortlist.append(any(e.place_id == winner for e in indexed.places))
        if shot.room in ("office_a", "office_b"):
            twins.append(_twin_line(len(table.place_ids), shot, brute))
    result.peak_mib = peak_rss_mib()
    return result


def _twin_line(size: int, shot: Shot, brute: QueryEvidence) -> str:
    def best_in(room: str) -> tuple[int, int]:
        ins = [(e.inliers, e.matches) for e in brute.places if e.room == room]
        return max(ins) if ins else (0, 0)

    a, b = best_in("office_a"), best_in("office_b")
    other = max(
        ((e.inliers, e.room) for e in brute.places if e.room not in ("office_a", "office_b")),
        default=(0, "-"),
    )
    top = top_room(brute)
    return (
        f"| {size} | {shot.room} ({shot.x_m:.2f}, {shot.y_m:.2f}) | {a[0]} ({a[1]}) | "
        f"{b[0]} ({b[1]}) | {other[0]} ({other[1]}) | {top} |"
    )


def pct(values: Sequence[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def print_table(results: Sequence[SizeResult], args: argparse.Namespace) -> None:
    print(
        f"\nqueries: building seed 0 under {args.condition!r}, {args.queries} per map; "
        f"SIFT on {CAMERA.width_px}x{CAMERA.height_px}; shortlist {args.shortlist}\n"
    )
    print(
        "| places | keypoints | index build s | index RSS MiB | brute median ms | brute p95 ms "
        "| indexed median ms | indexed p95 ms | retrieval median ms | speed-up (median) "
        "| top-1 room brute | top-1 room indexed | brute winner in shortlist | peak RSS MiB |"
    )
    print("|" + "---|" * 14)
    for r in results:
        n = len(r.brute_ok)
        print(
            f"| {r.size} | {r.keypoints} | {r.build_s:.2f} | {r.index_mib:.0f} "
            f"| {pct(r.brute_ms, 50):.0f} | {pct(r.brute_ms, 95):.0f} "
            f"| {pct(r.indexed_ms, 50):.0f} | {pct(r.indexed_ms, 95):.0f} "
            f"| {pct(r.retrieval_ms, 50):.1f} "
            f"| {pct(r.brute_ms, 50) / pct(r.indexed_ms, 50):.1f}x "
            f"| {sum(r.brute_ok)}/{n} | {sum(r.indexed_ok)}/{n} | {sum(r.in_shortlist)}/{n} "
            f"| {r.peak_mib:.0f} |"
        )


def main(argv: Sequence[str] | None = None) -> list[SizeResult]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="smoke run: 10 and 100 places")
    parser.add_argument("--sizes", default="10,100,1000", help="comma-separated map sizes")
    parser.add_argument("--queries", type=int, default=20, help="queries per map size")
    parser.add_argument("--condition", default="dim_noisy", help="the queries' condition")
    parser.add_argument("--shortlist", type=int, default=EvidenceParams().shortlist)
    parser.add_argument("--workers", type=int, default=2, help="render processes for the cache")
    parser.add_argument(
        "--cache-dir", type=Path, default=Path(tempfile.gettempdir()) / "toploc-bench-localize"
    )
    args = parser.parse_args(argv)
    if args.quick:
        args.sizes, args.queries = "10,100", 4
    sizes = [int(s) for s in args.sizes.split(",") if s.strip()]
    params = EvidenceParams(shortlist=args.shortlist)

    table, n_target = cached_table(args.cache_dir, max(sizes), args.workers)
    query_shots = shots(*TARGET[:2], 0.7, args.condition)
    pick = np.unique(np.round(np.linspace(0, len(query_shots) - 1, args.queries)).astype(int))
    query_shots = [query_shots[i] for i in pick]
    print(f"rendering {len(query_shots)} queries under {args.condition!r} ...", flush=True)
    queries = list(zip(query_shots, render_all(query_shots, args.workers), strict=True))

    results, twins = [], []
    for size in sizes:
        sub = table.subset(choose_places(len(table.place_ids), n_target, size))
        print(f"map of {size} places ({len(sub.descriptors)} keypoints) ...", flush=True)
        results.append(run_size(sub, queries, params, twins))
    print_table(results, args)
    if twins:
        print("\nlook-alike offices, brute force: best inliers (matches) per room\n")
        print("| places | query | office_a | office_b | best other room | top-1 |")
        print("|---|---|---|---|---|---|")
        print("\n".join(twins))
    return results


if __name__ == "__main__":
    main()
