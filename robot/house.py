"""The ``house`` world: a bare flat of eight rooms, painted walls instead of photo tilings.

A 13.2 x 2 m hall joins, to the north, ``bedroom_a``, ``bathroom_a``, ``bedroom_b`` and
``bathroom_b`` and, to the south, a ``living`` room, a ``kitchen`` (which also opens into the
living room) and a ``study``. The two bedrooms are identical in their own frames (walls, floor,
furniture, window, picture, door at the same place), and so are the two bathrooms: only what is
seen through their doors (the hall's far wall, the doors and pictures opposite) tells them apart.

Walls are paint (a plain colour per room with faint shading and noise; see
:mod:`robot.procedural_textures`) or, in the bathrooms, white tiles; floors are wood or tiles;
windows are near-white (overexposed) posters on the outer walls; cupboards, beds, tables and
counters are boxes; the front door is a door poster. A few pictures (scikit-image photographs)
hang in the hall, the living room, the study and the bedrooms. Places are 1.5 m apart; the
camera is 1.4 m up.

Building frame: the hall's south-west floor corner is the origin, x east along the hall, y north.
The seed only picks the pictures; the layout and materials are fixed.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from robot.world import Box, Door, Material, Poster, Room, World

ROOM_HEIGHT_M = 2.6
CAMERA_HEIGHT_M = 1.4
PLACE_SPACING_M = 1.5
PICTURES: tuple[str, ...] = ("astronaut", "chelsea", "coffee", "rocket", "hubble", "colorwheel")


def _paint(colour: str) -> Material:
    return Material(f"paint_{colour}", 3.0)


def _box(name: str, lo: tuple[float, ...], hi: tuple[float, ...], sides: str, top: str) -> Box:
    """A box with corners ``lo``, ``hi`` (x, y, z in the room frame, metres)."""
    tile_m = 3.0 if sides.startswith("paint") else 1.2
    return Box(name, (lo[0], lo[1], lo[2]), (hi[0], hi[1], hi[2]), Material(sides, tile_m),
               Material(top, tile_m))  # fmt: skip


def _window(name: str, wall: str, centre_m: float, width_m: float = 1.2) -> Poster:
    return Poster(name, wall, centre_m, 0.9, width_m, 1.3, "window")


def _picture(rng: np.random.Generator, name: str, wall: str, centre_m: float) -> Poster:
    width = float(rng.uniform(0.5, 0.8))
    return Poster(name, wall, centre_m, 1.3, width, 0.7 * width, str(rng.choice(PICTURES)))


def _room(
    name: str,
    origin: tuple[float, float],
    size: tuple[float, float],
    walls: Material,
    floor: Material,
    furniture: tuple[Box, ...] = (),
    posters: tuple[Poster, ...] = (),
) -> Room:
    ceiling = _paint("white")
    return Room(name, origin, size, ROOM_HEIGHT_M, (walls,) * 4, floor, ceiling, furniture, posters)


def _bedroom(rng: np.random.Generator, name: str, origin: tuple[float, float]) -> Room:
    """4.0 x 3.6 m: bed against the east wall, wardrobe by the door wall, a desk, a window."""
    furniture = (
        _box("bed", (2.45, 1.7, 0.0), (3.95, 3.55, 0.55), "wood_oak", "paint_lilac"),
        _box("wardrobe", (0.05, 0.05, 0.0), (1.25, 0.65, 2.1), "wood_walnut", "paint_white"),
        _box("nightstand", (3.5, 1.15, 0.0), (3.95, 1.6, 0.5), "wood_walnut", "wood_walnut"),
        _box("desk", (0.05, 2.4, 0.0), (0.7, 3.55, 0.75), "wood_oak", "wood_oak"),
    )
    posters = (
        _window("window", "+y", 1.6),
        _picture(rng, "picture", "+x", 2.6),
    )
    return _room(name, origin, (4.0, 3.6), _paint("rose"), Material("wood_oak", 1.6),
                 furniture, posters)  # fmt: skip


def _bathroom(name: str, origin: tuple[float, float]) -> Room:
    """2.6 x 2.8 m, white tiles: a bath along the east wall, a sink, a small window."""
    furniture = (
        _box("bath", (1.9, 1.0, 0.0), (2.55, 2.75, 0.55), "tiles_white", "paint_white"),
        _box("sink", (0.6, 2.35, 0.0), (1.2, 2.75, 0.85), "paint_white", "paint_white"),
        _box("cabinet", (0.6, 2.55, 1.4), (1.2, 2.75, 2.0), "paint_white", "paint_white"),
    )
    posters = (_window("window", "+y", 1.8, 0.6),)
    return _room(name, origin, (2.6, 2.8), Material("tiles_white", 1.2),
                 Material("tiles_slate", 1.6), furniture, posters)  # fmt: skip


def _hall(rng: np.random.Generator) -> Room:
    furniture = (
        _box("shoe_cupboard", (0.6, 1.6, 0.0), (1.6, 1.95, 0.9), "wood_walnut", "wood_walnut"),
        _box("coat_cupboard", (12.2, 0.05, 0.0), (13.15, 0.6, 2.2), "paint_white", "paint_white"),
    )
    posters = (
        Poster("front_door", "-x", 1.0, 0.0, 0.95, 2.05, "door"),
        _window("window", "+x", 1.2, 0.8),
        _picture(rng, "picture0", "+y", 6.3),
        _picture(rng, "picture1", "-y", 4.2),
        _picture(rng, "picture2", "-y", 6.5),
    )
    return _room("hall", (0.0, 0.0), (13.2, 2.0), _paint("cream"), Material("wood_oak", 1.6),
                 furniture, posters)  # fmt: skip


def _living(rng: np.random.Generator) -> Room:
    furniture = (
        _box("sofa", (0.8, 0.3, 0.0), (3.0, 1.2, 0.8), "paint_grey", "paint_grey"),
        _box("tv_cabinet", (0.05, 3.4, 0.0), (0.5, 4.8, 0.6), "wood_walnut", "wood_walnut"),
        _box("bookshelf", (5.6, 0.1, 0.0), (5.95, 1.6, 2.0), "wood_oak", "wood_oak"),
        _box("table", (3.8, 2.2, 0.0), (4.8, 3.2, 0.45), "wood_walnut", "wood_walnut"),
    )
    posters = (
        _window("window0", "-y", 3.6, 1.4),
        _window("window1", "-x", 2.5, 1.4),
        _picture(rng, "picture0", "+x", 4.2),
        _picture(rng, "picture1", "+y", 4.5),
    )
    return _room("living", (0.0, -5.0), (6.0, 5.0), _paint("sage"), Material("wood_oak", 1.6),
                 furniture, posters)  # fmt: skip


def _kitchen() -> Room:
    furniture = (
        _box("counter", (0.05, 0.05, 0.0), (3.2, 0.65, 0.9), "paint_white", "tiles_slate"),
        _box("wall_cupboard", (0.05, 0.05, 1.5), (1.6, 0.4, 2.2), "paint_white", "paint_white"),
        _box("fridge", (3.25, 0.05, 0.0), (3.95, 0.75, 1.85), "paint_grey", "paint_grey"),
        _box("table", (1.4, 2.0, 0.0), (2.6, 2.8, 0.75), "wood_oak", "wood_oak"),
    )
    posters = (_window("window", "-y", 2.5, 1.0),)
    return _room("kitchen", (6.0, -4.0), (4.0, 4.0), _paint("white"),
                 Material("tiles_slate", 1.6), furniture, posters)  # fmt: skip


def _study(rng: np.random.Generator) -> Room:
    furniture = (
        _box("desk", (1.7, 0.05, 0.0), (3.15, 0.75, 0.75), "wood_walnut", "wood_walnut"),
        _box("bookshelf", (0.05, 0.3, 0.0), (0.4, 2.3, 2.2), "wood_oak", "wood_oak"),
    )
    posters = (_window("window", "+x", 1.8, 1.0), _picture(rng, "picture", "+y", 2.2))
    return _room("study", (10.0, -3.5), (3.2, 3.5), _paint("sky"),
                 Material("wood_walnut", 1.6), furniture, posters)  # fmt: skip


def house_world(seed: int = 0) -> World:
    """The ``house`` flat (see the module docstring); ``seed`` picks the pictures."""
    rng = np.random.default_rng(seed)
    bedroom = _bedroom(rng, "bedroom_a", (0.0, 2.0))
    bathroom = _bathroom("bathroom_a", (4.0, 2.0))
    rooms = (
        _hall(rng),
        bedroom,
        bathroom,
        dataclasses.replace(bedroom, name="bedroom_b", origin_m=(6.6, 2.0)),
        dataclasses.replace(bathroom, name="bathroom_b", origin_m=(10.6, 2.0)),
        _living(rng),
        _kitchen(),
        _study(rng),
    )
    doors = (
        Door("hall", "bedroom_a", 3.3),
        Door("hall", "bathroom_a", 4.7),
        Door("hall", "bedroom_b", 6.6 + 3.3),
        Door("hall", "bathroom_b", 10.6 + 0.7),
        Door("hall", "living", 2.2, width_m=1.2),
        Door("hall", "kitchen", 8.4),
        Door("hall", "study", 10.6),
        Door("living", "kitchen", -2.2),
    )
    return World("house", rooms, doors, place_spacing_m=PLACE_SPACING_M,
                 camera_height_m=CAMERA_HEIGHT_M)  # fmt: skip
