"""Benchmark maps of 1,000 and 10,000 distinct places: a compact shortlist index over codes in RAM,
full fingerprints read from the SQLite map on demand (issue 22 §1).

How the map is made (every panorama rendered, nothing copied, rolled or jittered):

- The *target* building is ``building`` seed 0 (as in ``bench_localize.py``), one panorama per
  capture place of its 1 m grid, random headings, default light: 103 places.
- Then, seed by seed (1, 2, ...), the capture places (1 m grid) of ``building``, ``lab``,
  ``corridor`` and ``house`` built from that seed (other textures, posters and pictures), and one
  of the shipped photo rooms (a real 360° photo on a box, places on a 1 m grid inside it), their
  rooms named ``world#seed/room`` / ``photo/name``; until the map has 10,000 places. A map of
  ``n`` places is the first ``n`` of that list (so the 1,000-place map is the target building
  plus the first 897 distractors).
- Queries: the target building under another condition (``--condition``, default
  ``dim_noisy``) at the places of a 0.7 m grid (not the map's 1 m grid), random headings. A query
  whose best place is a distractor counts as wrong.

Fingerprints are SIFT (the ``sift`` preset) on 1024 x 192 px panoramas, cached in a map database
under ``--cache-dir`` (default ``$TOPLOC_HOME/cache/big-maps``).

    python benchmarks/bench_big_maps.py --render-only          # fill the cache (long)
    python benchmarks/bench_big_maps.py [--sizes 1000,10000] [--queries 40]
    python benchmarks/bench_big_maps.py --sizes 10000 --probes 16,8,4   # after a run
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import os
import sqlite3
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from process_memory import peak_rss_mib, rss_mib

from localizer.features import extract_preset
from localizer.robot_protocol import Pose2D
from mapdb.database import MapDatabase
from mapdb.records import Fingerprint, NewPlace
from mapdb.store import SqlitePlaceStore
from mapdb.workers import spawn_process_pool
from robot.conditions import get_condition, world_under
from robot.photo_library import load_photo, photo_room, photo_room_names
from robot.photo_room import render_photo_room
from robot.render import PanoramaCamera, render_panorama
from robot.scene import build_scene
from robot.world import capture_places
from robot.worlds import make_world
from toploc.evaluation.localization import OUTCOMES
from toploc.map_index import index_path

TARGET = ("building", 0, 1.0)
SEED_WORLDS = ("building", "lab", "corridor", "house")
PHOTO = "photo"
PHOTO_SPACING_M = 1.0
PHOTO_MARGIN_M = 0.6
CAMERA = PanoramaCamera(width_px=1024, height_px=192)
MAX_PLACES = 10_000


@dataclass(frozen=True)
class Shot:
    """One panorama to render: world (or ``"photo"``), seed, room, position (room frame, m) and
    heading (degrees)."""

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
        if self.world == PHOTO:
            return f"{PHOTO}/{self.room}"
        return f"{self.world}#{self.seed}/{self.room}"

    @property
    def source(self) -> str:
        """The map's ``source`` of this shot (unique per place)."""
        return f"{self.world}#{self.seed}/{self.room}/{self.x_m:.3f},{self.y_m:.3f}"


def _headings(key: Sequence[int], n: int) -> np.ndarray:
    return np.random.default_rng(list(key)).uniform(-180, 180, n)


def world_shots(world: str, seed: int, spacing_m: float, condition: str = "default") -> list[Shot]:
    """A shot at every capture place of the world's grid, seeded random headings."""
    places = capture_places(make_world(world, seed), spacing_m)
    headings = _headings([seed, 7, round(spacing_m * 100)], len(places))
    return [
        Shot(world, seed, p.room, p.x_m, p.y_m, float(h), condition)
        for p, h in zip(places, headings, strict=True)
    ]


def photo_shots(index: int) -> list[Shot]:
    """Shots on a 1 m grid inside photo room number ``index`` (manifest order), 0.6 m from its
    walls, seeded random headings."""
    name = photo_room_names()[index]
    room = photo_room(name)
    xs = np.arange(PHOTO_MARGIN_M, room.size_m[0] - PHOTO_MARGIN_M + 1e-9, PHOTO_SPACING_M)
    ys = np.arange(PHOTO_MARGIN_M, room.size_m[1] - PHOTO_MARGIN_M + 1e-9, PHOTO_SPACING_M)
    points = [(float(x), float(y)) for x in xs for y in ys]
    headings = _headings([index, 11], len(points))
    return [
        Shot(PHOTO, 0, name, x, y, float(h)) for (x, y), h in zip(points, headings, strict=True)
    ]


def map_shots(n_places: int = MAX_PLACES) -> list[Shot]:
    """The first ``n_places`` shots: the target building, then seed by seed the other worlds and
    a photo room."""
    result = world_shots(*TARGET)
    n_photos = len(photo_room_names())
    seed = 1
    while len(result) < n_places:
        for world in SEED_WORLDS:
            result += world_shots(world, seed, 1.0)
        if seed - 1 < n_photos:
            result += photo_shots(seed - 1)
        seed += 1
    return result[:n_places]


_SCENE: dict[tuple[str, int, str], object] = {}


def render_fingerprint(shot: Shot) -> Fingerprint:
    """Render ``shot`` and extract its SIFT fingerprint (one scene kept per process, so shots
    should come grouped by world and seed)."""
    condition = get_condition(shot.condition)
    noise_seed = (shot.seed, int(shot.x_m * 1000), int(shot.y_m * 1000), len(shot.room))
    if shot.world == PHOTO:
        pose = Pose2D(shot.x_m, shot.y_m, math.radians(shot.heading_deg))
        image = render_photo_room(
            load_photo(shot.room), photo_room(shot.room), pose, CAMERA, condition,
            seed=noise_seed, grey=True,
        )  # fmt: skip
        return extract_preset(image, "sift")
    key = (shot.world, shot.seed, shot.condition)
    world = make_world(shot.world, shot.seed)
    if key not in _SCENE:
        _SCENE.clear()
        _SCENE[key] = build_scene(world_under(world, condition, shot.seed))
    pose = world.building_pose(
        shot.room, Pose2D(shot.x_m, shot.y_m, math.radians(shot.heading_deg))
    )
    image = render_panorama(_SCENE[key], pose, CAMERA, condition, seed=noise_seed, grey=True)
    return extract_preset(image, "sift")


def render_all(items: Sequence[Shot], workers: int) -> Iterator[Fingerprint]:
    """Fingerprints of ``items`` in order, rendered by ``workers`` processes."""
    if workers <= 1:
        yield from map(render_fingerprint, items)
        return
    with spawn_process_pool(workers) as pool:
        yield from pool.map(render_fingerprint, items, chunksize=16)


def new_place(shot: Shot) -> NewPlace:
    return NewPlace(
        room=shot.label,
        image_sha256=hashlib.sha256(shot.source.encode()).hexdigest(),
        source=shot.source,
        x_m=shot.x_m,
        y_m=shot.y_m,
        heading_deg=shot.heading_deg,
    )


def cache_path(cache_dir: Path) -> Path:
    return cache_dir / f"big_maps_{CAMERA.width_px}x{CAMERA.height_px}.db"


def fill_cache(path: Path, n_places: int, workers: int) -> None:
    """Render the first ``n_places`` map shots not yet in the map at ``path`` into it."""
    items = map_shots(n_places)
    path.parent.mkdir(parents=True, exist_ok=True)
    with MapDatabase.open(path) as map_db:
        done = {p.source for p in map_db.places()}
        todo = [s for s in items if s.source not in done]
        print(f"{len(done)} places cached; rendering {len(todo)} into {path} ...", flush=True)
        t0 = time.perf_counter()
        for i, (shot, fp) in enumerate(zip(todo, render_all(todo, workers), strict=True)):
            map_db.add_place(new_place(shot), [fp])
            if (i + 1) % 200 == 0:
                rate = (i + 1) / (time.perf_counter() - t0)
                print(f"  {i + 1}/{len(todo)} ({rate:.1f}/s)", flush=True)
    print(f"cache complete: {len(items)} places in {path}", flush=True)


def default_cache_dir() -> Path:
    home = os.environ.get("TOPLOC_HOME")
    base = Path(home) if home else Path.home() / ".toploc"
    return base / "cache" / "big-maps"


def sized_map(big: Path, n_places: int) -> Path:
    """The map of the first ``n_places`` places of ``big`` (a copy beside it, made once by SQL;
    ``big`` itself when it has exactly that many)."""
    with MapDatabase.open(big, create=False, readonly=True) as map_db:
        held = map_db.info().n_places
    if held == n_places:
        return big
    if held < n_places:
        raise ValueError(f"{big} holds {held} places, {n_places} asked")
    path = big.with_name(f"{big.stem}_{n_places}.db")
    if path.exists():
        return path
    tmp = path.with_name(path.name + ".tmp")
    tmp.unlink(missing_ok=True)
    MapDatabase.open(tmp).close()  # the schema
    conn = sqlite3.connect(tmp)
    conn.execute("ATTACH DATABASE ? AS big", (str(big),))
    ids = "(SELECT id FROM big.places ORDER BY id LIMIT ?)"
    conn.execute(
        f"INSERT INTO rooms SELECT * FROM big.rooms WHERE id IN "
        f"(SELECT room_id FROM big.places WHERE id IN {ids})", (n_places,)
    )  # fmt: skip
    conn.execute(f"INSERT INTO places SELECT * FROM big.places WHERE id IN {ids}", (n_places,))
    conn.execute(
        f"INSERT INTO fingerprints SELECT * FROM big.fingerprints WHERE place_id IN {ids}",
        (n_places,),
    )
    conn.commit()
    conn.close()
    tmp.rename(path)
    return path


def query_images(cache_dir: Path, n: int, condition: str, workers: int) -> tuple[list[Shot], Path]:
    """``n`` query shots (the target under ``condition`` on a 0.7 m grid, spread evenly) and
    the file of their grey panoramas (rendered once)."""
    all_shots = world_shots(*TARGET[:2], 0.7, condition)
    pick = np.unique(np.round(np.linspace(0, len(all_shots) - 1, n)).astype(int))
    chosen = [all_shots[i] for i in pick]
    path = cache_dir / f"queries_{condition}_{len(chosen)}.npz"
    if not path.exists():
        print(f"rendering {len(chosen)} queries under {condition!r} ...", flush=True)
        if workers > 1:
            with spawn_process_pool(workers) as pool:
                images = list(pool.map(render_image, chosen, chunksize=4))
        else:
            images = [render_image(s) for s in chosen]
        np.savez_compressed(path, images=np.stack(images))
    return chosen, path


def render_image(shot: Shot) -> np.ndarray:
    """The grey panorama of a target-world shot."""
    condition = get_condition(shot.condition)
    world = make_world(shot.world, shot.seed)
    key = (shot.world, shot.seed, shot.condition)
    if key not in _SCENE:
        _SCENE.clear()
        _SCENE[key] = build_scene(world_under(world, condition, shot.seed))
    pose = world.building_pose(
        shot.room, Pose2D(shot.x_m, shot.y_m, math.radians(shot.heading_deg))
    )
    noise_seed = (shot.seed, int(shot.x_m * 1000), int(shot.y_m * 1000), len(shot.room))
    return render_panorama(_SCENE[key], pose, CAMERA, condition, seed=noise_seed, grey=True)


def run_one(args: argparse.Namespace) -> dict:
    """One map size and storage, in this (fresh) process: build the index if it is not cached,
    load the map, calibrate it, then run every query; the figures as a dict."""
    from dataclasses import replace

    from localizer.calibration import calibrate
    from localizer.evidence import place_evidence
    from localizer.localizer import Localizer, LocalizerConfig
    from toploc.evaluation.localization import QueryOutcome, outcome_of
    from toploc.map_index import compact_index
    from toploc.maps import load_map

    db_path, storage = Path(args.db), args.storage
    result: dict = {"places": args.size, "storage": storage, "load": os.getloadavg()[0]}
    if storage == "build":  # in a process of its own, so that its garbage is not measured
        t0 = time.perf_counter()
        _, report = compact_index(SqlitePlaceStore.open(db_path, "sift"))
        return {"index_build_s": time.perf_counter() - t0, "index_action": report.action,
                "build_peak_rss_mib": peak_rss_mib()}  # fmt: skip
    base = rss_mib()
    t0 = time.perf_counter()
    loaded = load_map(db_path, storage=storage)
    result["load_s"] = time.perf_counter() - t0
    result["resident_mib"] = rss_mib() - base
    result["kib_per_place"] = result["resident_mib"] * 1024 / args.size
    result["index_build_s"] = None  # FLANN: built within the load; compact: by "build"
    t0 = time.perf_counter()
    model, samples = calibrate(loaded)
    result["calibration_s"] = time.perf_counter() - t0
    result["pairs_by_test"] = dict(Counter(samples.pair_tests))
    groups = group_sizes(samples.lookalike_pairs, loaded.rooms)
    without_appearance = [
        pair for pair, test in zip(samples.lookalike_pairs, samples.pair_tests, strict=True)
        if test != "appearance"
    ]  # fmt: skip
    groups_without_appearance = group_sizes(without_appearance, loaded.rooms)
    loaded = replace(loaded, likelihood=model)
    localizer = Localizer(loaded, LocalizerConfig())
    # The same evidence read without look-alike groups: how much of the outcome they decide.
    plain = replace(model, lookalikes=(), counterparts=())
    untwinned = Localizer(replace(loaded, likelihood=plain), LocalizerConfig())
    result["lookalike_pairs"] = len(model.lookalikes)
    shots = json.loads(Path(args.shots).read_text())
    images = np.load(args.images)["images"]
    brute_file = Path(args.brute)
    brute = json.loads(brute_file.read_text()) if brute_file.exists() else {}
    rows = []
    for k, (shot, image) in enumerate(zip(shots, images, strict=True)):
        localizer.reset()
        t0 = time.perf_counter()
        fingerprint = localizer.extract(image)
        t1 = time.perf_counter()
        observation = localizer.observe_fingerprint(fingerprint, (t1 - t0) * 1e3)
        belief = localizer.update(observation)
        t2 = time.perf_counter()
        top = belief.rooms[int(np.argmax(belief.probabilities))]
        query = QueryOutcome(
            f"q{k}", shot["room"], top, max(belief.probabilities), str(belief.state),
            observation.timing_ms,
        )  # fmt: skip
        outcome = outcome_of(query, loaded.rooms)
        best = observation.evidence.best
        untwinned.reset()
        plain_belief = untwinned.update(observation)
        plain_top = plain_belief.rooms[int(np.argmax(plain_belief.probabilities))]
        plain_query = QueryOutcome(
            f"q{k}", shot["room"], plain_top, max(plain_belief.probabilities),
            str(plain_belief.state), observation.timing_ms,
        )  # fmt: skip
        row = {
            "extract_ms": (t1 - t0) * 1e3,
            "total_ms": (t2 - t0) * 1e3,
            "retrieval_ms": observation.timing_ms["retrieval"],
            "verification_ms": observation.timing_ms["verification"],
            "top1": best is not None and best.inliers > 0 and best.room == shot["room"],
            "outcome": outcome,
            "predicted": top,
            "outcome_without_lookalikes": outcome_of(plain_query, loaded.rooms),
            "shortlist": [e.place_id for e in observation.evidence.places],
            "group_size": groups.get(shot["room"], 1),
            "group_size_without_appearance": groups_without_appearance.get(shot["room"], 1),
        }
        if storage == "memory" and k < args.brute_queries and str(k) not in brute:
            evidence = place_evidence(fingerprint, loaded.table, localizer.evidence_params)
            brute[str(k)] = evidence.best.place_id if evidence.best else None
        if str(k) in brute:
            row["brute_in_shortlist"] = brute[str(k)] in row["shortlist"]
        rows.append(row)
    if storage == "memory":
        brute_file.write_text(json.dumps(brute))
    result["queries"] = rows
    result["peak_rss_mib"] = peak_rss_mib()
    return result


def probe_sweep(db: Path, shots: list[Shot], images: Path, probes: Sequence[int]) -> None:
    """Retrieval time, evidence time, top-1 (best place) and shortlist overlap with the first
    setting, per probe count, on the map at ``db`` (its index file, not calibrated)."""
    from localizer.evidence import place_evidence
    from localizer.localizer import Localizer, LocalizerConfig
    from localizer.retrieval import CompactParams, CompactPlaceIndex
    from toploc.maps import load_map

    store = SqlitePlaceStore.open(db, "sift")
    with np.load(index_path(db, "sift")) as data:
        codes, counts = data["index"], data["keypoint_counts"]
    localizer = Localizer(load_map(db, storage="disk"), LocalizerConfig())
    fingerprints = [localizer.extract(image) for image in np.load(images)["images"]]
    first: list[set[int]] = []
    for n in probes:
        index = CompactPlaceIndex.from_bytes(codes, counts, CompactParams(probes=n))
        retrieval_ms, evidence_ms, right, lists = [], [], 0, []
        for fingerprint, shot in zip(fingerprints, shots, strict=True):
            t0 = time.perf_counter()
            lists.append(set(index.shortlist(fingerprint.descriptors, 10).tolist()))
            t1 = time.perf_counter()
            evidence = place_evidence(fingerprint, store, localizer.evidence_params, index)
            t2 = time.perf_counter()
            retrieval_ms.append((t1 - t0) * 1e3)
            evidence_ms.append((t2 - t1) * 1e3)
            best = evidence.best
            right += best is not None and best.inliers > 0 and best.room == shot.room
        first = first or lists
        overlap = np.mean([len(a & b) / 10 for a, b in zip(lists, first, strict=True)])
        print(
            f"probes {n}: retrieval median {np.median(retrieval_ms):.0f} ms, evidence median "
            f"{np.median(evidence_ms):.0f} ms, top-1 {right}/{len(shots)}, shortlist overlap "
            f"with {probes[0]} probes {overlap:.2f}",
            flush=True,
        )


def group_sizes(pairs: Sequence[tuple[str, str]], rooms: Sequence[str]) -> dict[str, int]:
    """Per room in a look-alike group of ``pairs``, the number of rooms in its group."""
    from localizer.lookalikes import lookalike_groups

    return {rooms[i]: len(g) for g in lookalike_groups(pairs, rooms) for i in g}


def lookalike_line(r: dict) -> str:
    """Which tests made the look-alike pairs, and how many queries' rooms they group."""
    grouped = [q for q in r["queries"] if q.get("group_size", 1) > 1]
    alone = sum(q.get("group_size_without_appearance", 1) == 1 for q in grouped)
    sizes = [q["group_size"] for q in grouped] or [1]
    tests = ", ".join(f"{n} by {t}" for t, n in sorted(r.get("pairs_by_test", {}).items()))
    return (
        f"{r['places']} places, {r['storage']}: look-alike pairs {tests or 'none'}; "
        f"{len(grouped)}/{len(r['queries'])} queries' rooms in a group (median "
        f"{np.median(sizes):.0f} rooms), {alone} of them in none without the pairs by appearance"
    )


def summarise(r: dict) -> str:
    rows = r["queries"]
    ratio = [q["total_ms"] / q["extract_ms"] for q in rows]
    outcomes = {o: sum(q["outcome"] == o for q in rows) for o in OUTCOMES}
    plain = {o: sum(q.get("outcome_without_lookalikes") == o for q in rows) for o in OUTCOMES}
    recall = [q["brute_in_shortlist"] for q in rows if "brute_in_shortlist" in q]
    build = "-" if r["index_build_s"] is None else f"{r['index_build_s']:.0f}"
    return (
        f"| {r['places']} | {r['storage']} | {sum(q['top1'] for q in rows)}/{len(rows)} "
        f"| {' / '.join(str(outcomes[o]) for o in OUTCOMES)} "
        f"| {r.get('lookalike_pairs', '-')} | {' / '.join(str(plain[o]) for o in OUTCOMES)} "
        f"| {f'{sum(recall)}/{len(recall)}' if recall else '-'} "
        f"| {np.median([q['extract_ms'] for q in rows]):.0f} "
        f"| {np.median([q['retrieval_ms'] for q in rows]):.0f} "
        f"| {np.median([q['total_ms'] for q in rows]):.0f} "
        f"| {np.median(ratio):.2f}x | {np.percentile(ratio, 95):.2f}x "
        f"| {r['kib_per_place']:.1f} | {r['peak_rss_mib']:.0f} "
        f"({r.get('build_peak_rss_mib', 0):.0f}) | {r['load_s']:.1f} | {build} "
        f"| {r['calibration_s']:.0f} | {r['load']:.1f} |"
    )


HEADER = (
    "| places | storage | top-1 room | right loc. / right amb. / wrong loc. / wrong amb. / lost "
    "| look-alike pairs | the same without look-alike groups "
    "| brute winner in shortlist | extraction ms | retrieval ms | query ms (median) "
    "| query / extraction median | p95 | resident KiB per place | peak RSS MiB (build) | load s "
    "| index build s | calibration s | load avg |\n" + "|---" * 18 + "|"
)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--render-only", action="store_true", help="fill the cache and stop")
    parser.add_argument("--sizes", default="1000,10000", help="comma-separated map sizes")
    parser.add_argument(
        "--memory-sizes", default="1000", help="sizes also run in memory (FLANN), as today"
    )
    parser.add_argument("--queries", type=int, default=40, help="queries per map")
    parser.add_argument(
        "--brute-queries", type=int, default=20, help="queries also matched brute force (memory)"
    )
    parser.add_argument("--condition", default="dim_noisy", help="the queries' condition")
    parser.add_argument("--workers", type=int, default=2, help="render processes")
    parser.add_argument("--cache-dir", type=Path, default=None)
    parser.add_argument(
        "--keep-index", action="store_true", help="reuse an index file left by an earlier run"
    )
    parser.add_argument(
        "--probes", default=None, help="instead: sweep these probe counts (e.g. 16,8,4) on the "
        "largest size's index file, uncalibrated"
    )  # fmt: skip
    parser.add_argument("--out", type=Path, default=None, help="write the results as JSON")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    for name in ("--db", "--storage", "--shots", "--images", "--brute", "--result"):
        parser.add_argument(name, help=argparse.SUPPRESS)
    parser.add_argument("--size", type=int, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        Path(args.result).write_text(json.dumps(run_one(args)))
        return
    cache_dir = args.cache_dir or default_cache_dir()
    sizes = [int(s) for s in args.sizes.split(",") if s.strip()]
    memory_sizes = [int(s) for s in args.memory_sizes.split(",") if s.strip()]
    big = cache_path(cache_dir)
    fill_cache(big, max(sizes), args.workers)
    if args.render_only:
        return
    shots, images = query_images(cache_dir, args.queries, args.condition, args.workers)
    shots_file = cache_dir / "query_shots.json"
    shots_file.write_text(json.dumps([dataclasses.asdict(s) for s in shots]))
    if args.probes:
        probe_sweep(
            sized_map(big, max(sizes)), shots, images, [int(p) for p in args.probes.split(",")]
        )
        return
    results = []
    for size in sizes:
        db = sized_map(big, size)
        brute = cache_dir / f"brute_{size}_{args.condition}_{len(shots)}.json"
        for storage in (["memory"] if size in memory_sizes else []) + ["disk"]:
            print(f"map of {size} places, {storage} ...", flush=True)
            out = cache_dir / f"result_{size}_{storage}.json"
            if storage == "disk" and not args.keep_index:
                index_path(db, "sift").unlink(missing_ok=True)  # time the build
            command = [
                sys.executable, __file__, "--child", "--db", str(db), "--storage", storage,
                "--size", str(size), "--shots", str(shots_file), "--images", str(images),
                "--brute", str(brute), "--brute-queries", str(args.brute_queries),
                "--result", str(out),
            ]  # fmt: skip
            built = {}
            if storage == "disk":
                subprocess.run([*command[:6], "build", *command[7:]], check=True)
                built = json.loads(out.read_text())
            subprocess.run(command, check=True)
            results.append(json.loads(out.read_text()) | built)
            print(HEADER.splitlines()[0])
            print(summarise(results[-1]), flush=True)
    print(f"\nqueries: building seed 0 under {args.condition!r}, {len(shots)} per map, "
          f"SIFT on {CAMERA.width_px}x{CAMERA.height_px}\n")  # fmt: skip
    print(HEADER)
    for r in results:
        print(summarise(r))
    print()
    for r in results:
        print(lookalike_line(r))
    if args.out:
        args.out.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main(sys.argv[1:])
