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
"""

from __future__ import annotations

import argparse
import hashlib
import math
import os
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from localizer.features import extract_preset
from localizer.robot_protocol import Pose2D
from mapdb.database import MapDatabase
from mapdb.records import Fingerprint, NewPlace
from mapdb.workers import spawn_process_pool
from robot.conditions import get_condition, world_under
from robot.photo_library import load_photo, photo_room, photo_room_names
from robot.photo_room import render_photo_room
from robot.render import PanoramaCamera, render_panorama
from robot.scene import build_scene
from robot.world import capture_places
from robot.worlds import make_world

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


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--render-only", action="store_true", help="fill the cache and stop")
    parser.add_argument("--sizes", default="1000,10000", help="comma-separated map sizes")
    parser.add_argument("--workers", type=int, default=2, help="render processes")
    parser.add_argument("--cache-dir", type=Path, default=None)
    args = parser.parse_args(argv)
    cache_dir = args.cache_dir or default_cache_dir()
    sizes = [int(s) for s in args.sizes.split(",") if s.strip()]
    fill_cache(cache_path(cache_dir), max(sizes), args.workers)
    if args.render_only:
        return


if __name__ == "__main__":
    main(sys.argv[1:])
