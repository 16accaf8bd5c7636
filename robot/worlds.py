"""Named preset worlds, deterministic from a seed: ``lab``, ``square``, ``corridor``, ``building``,
``house`` (bare painted rooms, :mod:`robot.house`).

- ``square``: a small 4.0 x 3.4 m room with a table and a cabinet.
- ``lab``: a large 10 x 11 m lab with rows of benches, shelves and two pillars.
- ``corridor``: a 22.5 x 2.2 m corridor with notice boards, closed doors and a bench.
- ``building``: a corridor joining two look-alike offices (``office_a`` and ``office_b``: same
  size, textures, furniture and posters in their own frames, doors at the same place), a kitchen,
  a seminar room and a storage room, with doors between them.

The seed picks the textures, the posters and small jitters of the layout; the layout itself is
fixed. Room frames have their origin at the room's corner of smallest building x and y.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from robot.house import house_world
from robot.world import WALL_SIDES, Box, Door, Material, Poster, Room, World

WALL_TEXTURES = ("brick", "gravel", "moon", "coins", "text", "page", "grass")
FLOOR_TEXTURES = ("gravel", "grass", "brick", "coins")
PICTURES: tuple[str, ...] = ("astronaut", "chelsea", "coffee", "rocket", "camera", "cat")
PICTURES += ("clock", "hubble", "cells", "colorwheel", "retina", "logo")

Spans = dict[str, list[tuple[float, float]]]


def _walls(rng: np.random.Generator) -> tuple[Material, Material, Material, Material]:
    """Four distinct wall materials, tiles 0.8 to 1.6 m."""
    a, b, c, d = (
        Material(str(name), float(rng.uniform(0.8, 1.6)))
        for name in rng.choice(WALL_TEXTURES, size=4, replace=False)
    )
    return a, b, c, d


def _floor(rng: np.random.Generator) -> Material:
    return Material(str(rng.choice(FLOOR_TEXTURES)), float(rng.uniform(0.8, 1.5)))


def _posters(
    rng: np.random.Generator, room: Room, per_wall: int, avoid: Spans
) -> tuple[Poster, ...]:
    """Up to ``per_wall`` pictures per wall in even slots, clear of the ``avoid`` spans."""
    posters: list[Poster] = []
    for side in WALL_SIDES:
        length = room.size_m[1] if side[1] == "x" else room.size_m[0]
        slot = length / per_wall
        for k in range(per_wall):
            width = float(min(rng.uniform(0.5, 1.0), slot - 0.3))
            centre = (k + 0.5) * slot + float(rng.uniform(-0.1, 0.1))
            lo, hi = centre - width / 2 - 0.1, centre + width / 2 + 0.1
            if width < 0.3 or any(lo < b and a < hi for a, b in avoid.get(side, [])):
                continue
            posters.append(
                Poster(
                    name=f"poster{len(posters)}",
                    wall=side,
                    center_m=centre,
                    bottom_m=float(rng.uniform(1.0, 1.4)),
                    width_m=width,
                    height_m=float(rng.uniform(0.4, 0.8)),
                    texture=str(rng.choice(PICTURES)),
                )
            )
    return tuple(posters)


def _door_spans(world: World, room: Room) -> Spans:
    """Door openings of ``room`` per wall side, as room-frame intervals along the wall."""
    spans: Spans = {}
    x0, x1, y0, y1 = room.bounds_m
    for door in world.doors:
        if room.name not in (door.room_a, door.room_b):
            continue
        wall = world.door_wall(door)
        coords = (x0, x1) if wall.axis == 0 else (y0, y1)
        side = ("-", "+")[int(abs(wall.coord_m - coords[1]) < 1e-6)] + "xy"[wall.axis]
        offset = room.origin_m[1 - wall.axis]
        half = door.width_m / 2
        spans.setdefault(side, []).append(
            (door.center_m - half - offset, door.center_m + half - offset)
        )
    return spans


def _box(
    name: str,
    lo: tuple[float, float, float],
    hi: tuple[float, float, float],
    sides: str,
    top: str,
    tile_m: float = 0.6,
) -> Box:
    return Box(name, lo, hi, Material(sides, tile_m), Material(top, tile_m))


def _room(
    rng: np.random.Generator,
    name: str,
    origin: tuple[float, float],
    size: tuple[float, float],
    height_m: float,
    furniture: tuple[Box, ...] = (),
) -> Room:
    """A room with seeded wall and floor materials and a plain white ceiling."""
    walls, floor = _walls(rng), _floor(rng)
    return Room(name, origin, size, height_m, walls, floor, Material("white"), furniture)


def _small_room(rng: np.random.Generator, name: str, origin: tuple[float, float]) -> Room:
    """A 4.0 x 3.4 x 2.5 m room with a table and a cabinet (no posters yet)."""
    dx, dy = rng.uniform(-0.1, 0.1, size=2)
    furniture = (
        _box("table", (0.5 + dx, 0.4 + dy, 0.0), (1.7 + dx, 1.2 + dy, 0.75), "grey", "coffee", 0.8),
        _box("cabinet", (3.5, 2.2, 0.0), (3.95, 3.3, 1.9), str(rng.choice(WALL_TEXTURES)), "grey"),
    )
    return _room(rng, name, origin, (4.0, 3.4), 2.5, furniture)


def _with_posters(world: World, rng: np.random.Generator, per_wall: dict[str, int]) -> World:
    """``world`` with seeded posters on the walls of the rooms named in ``per_wall``."""
    rooms = tuple(
        dataclasses.replace(
            r, posters=r.posters + _posters(rng, r, per_wall[r.name], _door_spans(world, r))
        )
        if r.name in per_wall
        else r
        for r in world.rooms
    )
    return dataclasses.replace(world, rooms=rooms)


def square_world(seed: int = 0) -> World:
    """One small 4.0 x 3.4 m room; capture grid 0.5 m."""
    rng = np.random.default_rng(seed)
    world = World("square", (_small_room(rng, "square", (0.0, 0.0)),), place_spacing_m=0.5)
    return _with_posters(world, rng, {"square": 2})


def lab_world(seed: int = 0) -> World:
    """A 10 x 11 x 3 m lab: three rows of benches, shelves, cabinets and two pillars; grid 1 m."""
    rng = np.random.default_rng(seed)
    bench_sides, bench_top = (str(t) for t in rng.choice(("grey", "brick", "coins"), size=2))
    furniture = [
        _box(f"bench{i}{j}", (x, y, 0.0), (x + 2.4, y + 0.8, 0.9), bench_sides, bench_top)
        for i, y in enumerate((2.6, 5.1, 7.6))
        for j, x in enumerate((2.0, 5.6))
    ]
    furniture += [
        _box("shelf", (1.0, 10.55, 0.0), (4.5, 10.95, 2.1), "page", "grey", 1.0),
        _box("cabinet", (0.05, 4.0, 0.0), (0.55, 6.0, 1.2), str(rng.choice(WALL_TEXTURES)), "text"),
        _box("pillar0", (4.8, 4.0, 0.0), (5.2, 4.4, 3.0), "brick", "grey", 0.8),
        _box("pillar1", (4.8, 6.5, 0.0), (5.2, 6.9, 3.0), "brick", "grey", 0.8),
        _box("printer", (8.9, 0.1, 0.0), (9.8, 0.8, 1.1), "white", "black"),
    ]
    lab = _room(rng, "lab", (0.0, 0.0), (10.0, 11.0), 3.0, tuple(furniture))
    return _with_posters(World("lab", (lab,), place_spacing_m=1.0), rng, {"lab": 4})


def corridor_world(seed: int = 0) -> World:
    """A 22.5 x 2.2 x 2.6 m corridor (long axis x) with closed doors and a bench; grid 1 m."""
    rng = np.random.default_rng(seed)
    furniture = (
        _box("bench", (9.0, 0.05, 0.0), (10.6, 0.45, 0.45), "brick", "gravel"),
        _box("extinguisher", (14.0, 2.0, 0.3), (14.2, 2.15, 0.9), "red", "black"),
    )
    corridor = _room(rng, "corridor", (0.0, 0.0), (22.5, 2.2), 2.6, furniture)
    closed_doors = tuple(
        Poster(f"door{k}", "+y" if k % 2 else "-y", x, 0.0, 0.9, 2.0, "grey")
        for k, x in enumerate((3.0, 7.5, 12.0, 16.5, 20.0))
    )
    spans: Spans = {}
    for door in closed_doors:
        spans.setdefault(door.wall, []).append((door.center_m - 0.5, door.center_m + 0.5))
    posters = closed_doors + _posters(rng, corridor, 6, spans)
    return World("corridor", (dataclasses.replace(corridor, posters=posters),))


def building_world(seed: int = 0) -> World:
    """A corridor joining look-alike ``office_a`` and ``office_b``, a kitchen, a seminar room and
    a storage room (which also opens into the seminar room); grid 1 m."""
    rng = np.random.default_rng(seed)
    corridor = _room(rng, "corridor", (0.0, 0.0), (14.0, 2.2), 2.6)
    office = _small_room(rng, "office_a", (0.0, 2.2))
    kitchen = _room(rng, "kitchen", (8.0, 2.2), (6.0, 4.5), 2.6, (
        _box("counter", (0.05, 3.8, 0.0), (4.0, 4.45, 0.9), "white", "gravel"),
        _box("fridge", (5.2, 3.7, 0.0), (5.95, 4.45, 1.8), "white", "grey"),
        _box("table", (2.0, 1.5, 0.0), (3.2, 2.3, 0.75), "grey", "coffee", 0.8),
    ))  # fmt: skip
    desks = tuple(
        _box(f"desk{i}", (1.2 + 1.6 * i, 1.8, 0.0), (2.4 + 1.6 * i, 2.5, 0.75), "grey", "page")
        for i in range(3)
    )
    seminar = _room(rng, "seminar", (0.0, -5.0), (7.0, 5.0), 2.8, desks)
    storage = _room(rng, "storage", (7.0, -3.0), (7.0, 3.0), 2.6, (
        _box("rack0", (0.5, 0.05, 0.0), (3.0, 0.6, 2.0), "coins", "grey"),
        _box("rack1", (4.0, 0.05, 0.0), (6.5, 0.6, 2.0), "text", "grey"),
    ))  # fmt: skip
    doors = (
        Door("corridor", "office_a", 2.9),
        Door("corridor", "office_b", 6.9),
        Door("corridor", "kitchen", 10.0),
        Door("corridor", "seminar", 5.5),
        Door("corridor", "storage", 12.0),
        Door("seminar", "storage", -1.5),
    )
    office_b = dataclasses.replace(office, name="office_b", origin_m=(4.0, 2.2))
    rooms: tuple[Room, ...] = (corridor, office, office_b, kitchen, seminar, storage)
    world = World("building", rooms, doors, place_spacing_m=1.0)
    per_wall = {"corridor": 5, "office_a": 2, "kitchen": 2, "seminar": 3, "storage": 2}
    world = _with_posters(world, rng, per_wall)
    office_a = world.room("office_a")
    office_b = dataclasses.replace(office_a, name="office_b", origin_m=(4.0, 2.2))
    rooms = tuple(office_b if r.name == "office_b" else r for r in world.rooms)
    return dataclasses.replace(world, rooms=rooms)


WORLDS: dict[str, Callable[[int], World]] = {
    "lab": lab_world,
    "square": square_world,
    "corridor": corridor_world,
    "building": building_world,
    "house": house_world,
}
WORLD_NAMES: tuple[str, ...] = tuple(WORLDS)


def make_world(name: str, seed: int = 0) -> World:
    """The preset world called ``name`` built from ``seed``; ``ValueError`` for unknown names."""
    try:
        builder = WORLDS[name]
    except KeyError:
        raise ValueError(
            f"unknown world {name!r}; known worlds: {', '.join(WORLD_NAMES)}"
        ) from None
    return builder(seed)
