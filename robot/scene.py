"""A :class:`~robot.world.World` compiled into flat arrays of textured rectangles for rendering.

Every surface becomes a *quad*: an axis-aligned rectangle in a plane ``axis = coord_m`` of the
building frame (axis 0: x, 1: y, 2: z), one-sided, visible from the side its normal
(``normal_sign`` along ``axis``) points to. Its extent is ``[lo_m, hi_m]`` in the two other
building coordinates, in increasing axis order: (y, z) for axis 0, (x, z) for axis 1, (x, y) for
axis 2. Texture coordinates of a point P on a quad are ``u = (P - uv_origin_m) . u_axis`` and
``v = (P - uv_origin_m) . v_axis`` metres, one texture tile per ``tile_m``; ``u`` runs to the
viewer's right and ``v`` up on walls, so pictures are neither mirrored nor upside down.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from robot.textures import TextureAtlas, build_atlas
from robot.world import WALL_SIDES, Box, Material, Poster, Room, World

POSTER_INSET_M = 0.005
EMISSIVE_SHADE = 1.25  # brightness factor of light sources (windows): brighter than white, clips
EMISSIVE_TEXTURES = frozenset({"window"})
_LIGHT_DIR = np.array([0.35, 0.2, 0.91]) / np.linalg.norm([0.35, 0.2, 0.91])


@dataclass(frozen=True)
class _Quad:
    """One quad while compiling; see the module docstring for the fields."""

    axis: int
    coord_m: float
    normal_sign: int
    lo_m: tuple[float, float]
    hi_m: tuple[float, float]
    material: Material
    uv_origin_m: tuple[float, float, float]
    room_index: int
    label: str
    full_height: bool = False
    tile_m: tuple[float, float] | None = None  # default: the material's square tile


@dataclass(frozen=True)
class Scene:
    """Quads of a world as arrays of length K (one entry per quad), plus room footprints."""

    axis: np.ndarray  # (K,) int: plane axis
    coord_m: np.ndarray  # (K,) plane position
    normal_sign: np.ndarray  # (K,) +1 / -1: side the quad is seen from
    lo_m: np.ndarray  # (K, 2) in-plane lower bounds
    hi_m: np.ndarray  # (K, 2) in-plane upper bounds
    full_height: np.ndarray  # (K,) bool: vertical quad from floor to its room's ceiling
    texture_index: np.ndarray  # (K,) index into atlas
    tile_m: np.ndarray  # (K, 2) tile size along u, v
    uv_origin_m: np.ndarray  # (K, 3)
    u_axis: np.ndarray  # (K, 3) unit vector
    v_axis: np.ndarray  # (K, 3) unit vector
    shade: np.ndarray  # (K,) float32 brightness from a fixed light direction (windows: emissive)
    room_index: np.ndarray  # (K,) room the quad belongs to
    labels: tuple[str, ...]  # (K,) e.g. "lab/wall-x", "lab/desk1/top", "lab/poster3"
    room_names: tuple[str, ...]
    room_bounds_m: np.ndarray  # (R, 4) building-frame x_min, x_max, y_min, y_max
    atlas: TextureAtlas

    @property
    def n_quads(self) -> int:
        """Number of quads."""
        return len(self.axis)

    def room_of(self, x_m: float, y_m: float) -> int:
        """Index of the room strictly containing the building-frame point, or -1."""
        b = self.room_bounds_m
        inside = (b[:, 0] < x_m) & (x_m < b[:, 1]) & (b[:, 2] < y_m) & (y_m < b[:, 3])
        hits = np.flatnonzero(inside)
        return int(hits[0]) if len(hits) else -1


def _wall_quads(world: World, room: Room, index: int) -> list[_Quad]:
    """The walls of ``room`` split around its door openings."""
    x0, x1, y0, y1 = room.bounds_m
    quads = []
    for side, material in zip(WALL_SIDES, room.walls, strict=True):
        axis = 0 if side[1] == "x" else 1
        coord = (x0, x1, y0, y1)[WALL_SIDES.index(side)]
        normal = 1 if side[0] == "-" else -1  # walls face into the room
        lo, hi = (y0, y1) if axis == 0 else (x0, x1)
        openings = sorted(_openings(world, room, axis, coord))
        cuts = [lo, *[v for d0, d1, _ in openings for v in (d0, d1)], hi]
        label = f"{room.name}/wall{side}"
        wall = partial(
            _Quad,
            axis,
            coord,
            normal,
            material=material,
            uv_origin_m=(x0, y0, 0.0),
            room_index=index,
        )
        for a, b in zip(cuts[::2], cuts[1::2], strict=True):
            if b - a > 1e-9:
                quads.append(wall((a, 0.0), (b, room.height_m), label=label, full_height=True))
        for d0, d1, top in openings:
            quads.append(wall((d0, top), (d1, room.height_m), label=f"{label}/lintel"))
    return quads


def _openings(
    world: World, room: Room, axis: int, coord: float
) -> list[tuple[float, float, float]]:
    """Door openings ``(lo, hi, top_m)`` in the wall ``axis = coord`` of ``room``."""
    found = []
    for door in world.doors:
        if room.name not in (door.room_a, door.room_b):
            continue
        wall = world.door_wall(door)
        if wall.axis == axis and abs(wall.coord_m - coord) < 1e-6:
            half = door.width_m / 2
            found.append((door.center_m - half, door.center_m + half, door.height_m))
    return found


def _box_quads(room: Room, box: Box, index: int) -> list[_Quad]:
    """Sides, top (and bottom, if it floats) of a box, facing outwards."""
    ox, oy = room.origin_m
    (x0, y0, z0), (x1, y1, z1) = box.min_m, box.max_m
    x0, x1, y0, y1 = x0 + ox, x1 + ox, y0 + oy, y1 + oy
    label = f"{room.name}/{box.name}"
    full = z0 <= 0 and z1 >= room.height_m
    side = partial(
        _Quad, material=box.sides, uv_origin_m=(x0, y0, z0), room_index=index, full_height=full
    )
    face = partial(_Quad, material=box.top, uv_origin_m=(x0, y0, z0), room_index=index)
    quads = [
        side(0, x0, -1, (y0, z0), (y1, z1), label=f"{label}/side-x"),
        side(0, x1, 1, (y0, z0), (y1, z1), label=f"{label}/side+x"),
        side(1, y0, -1, (x0, z0), (x1, z1), label=f"{label}/side-y"),
        side(1, y1, 1, (x0, z0), (x1, z1), label=f"{label}/side+y"),
    ]
    if z1 < room.height_m:
        quads.append(face(2, z1, 1, (x0, y0), (x1, y1), label=f"{label}/top"))
    if z0 > 0:
        quads.append(face(2, z0, -1, (x0, y0), (x1, y1), label=f"{label}/bottom"))
    return quads


def _poster_quad(room: Room, poster: Poster, index: int) -> _Quad:
    """A poster just in front of its wall, its texture stretched once over it."""
    side = WALL_SIDES.index(poster.wall)
    axis = 0 if side < 2 else 1
    normal = 1 if poster.wall[0] == "-" else -1
    coord = room.bounds_m[side] + normal * POSTER_INSET_M
    along = poster.center_m + room.origin_m[1 - axis]
    half, bottom = poster.width_m / 2, poster.bottom_m
    centre = np.array([coord, along, bottom] if axis == 0 else [along, coord, bottom])
    origin = centre - half * _u_axis(axis, normal)
    return _Quad(
        axis,
        coord,
        normal,
        (along - half, bottom),
        (along + half, bottom + poster.height_m),
        material=Material(poster.texture),
        uv_origin_m=(float(origin[0]), float(origin[1]), float(origin[2])),
        room_index=index,
        label=f"{room.name}/{poster.name}",
        tile_m=(poster.width_m, poster.height_m),
    )


def _u_axis(axis: int, normal: int) -> np.ndarray:
    """Texture u direction: the viewer's right when facing the quad (for floors: +x)."""
    if axis == 0:
        return np.array([0.0, normal, 0.0])
    if axis == 1:
        return np.array([-normal, 0.0, 0.0])
    return np.array([1.0, 0.0, 0.0])


def _room_quads(world: World, room: Room, index: int) -> list[_Quad]:
    """All quads of a room: walls, floor, ceiling, furniture and posters."""
    x0, x1, y0, y1 = room.bounds_m
    flat = partial(
        _Quad, 2, lo_m=(x0, y0), hi_m=(x1, y1), uv_origin_m=(x0, y0, 0.0), room_index=index
    )
    quads = _wall_quads(world, room, index)
    quads.append(flat(0.0, 1, material=room.floor, label=f"{room.name}/floor"))
    quads.append(flat(room.height_m, -1, material=room.ceiling, label=f"{room.name}/ceiling"))
    quads += [q for box in room.furniture for q in _box_quads(room, box, index)]
    quads += [_poster_quad(room, poster, index) for poster in room.posters]
    return quads


def build_scene(world: World) -> Scene:
    """Compile ``world`` into a :class:`Scene` (loads and mip-maps its textures, cached)."""
    quads = [q for i, room in enumerate(world.rooms) for q in _room_quads(world, room, i)]
    atlas = build_atlas(q.material.texture for q in quads)
    axis = np.array([q.axis for q in quads], np.int64)
    normal = np.array([q.normal_sign for q in quads], np.int64)
    u_axis = np.stack([_u_axis(a, n) for a, n in zip(axis, normal, strict=True)])
    v_axis = np.tile([0.0, 0.0, 1.0], (len(quads), 1))  # walls: up
    v_axis[(axis == 2) & (normal > 0)] = [0.0, 1.0, 0.0]  # floors and tops, seen from above
    v_axis[(axis == 2) & (normal < 0)] = [0.0, -1.0, 0.0]  # ceilings, seen from below
    normals = np.zeros((len(quads), 3))
    normals[np.arange(len(quads)), axis] = normal
    shade = 0.6 + 0.4 * np.clip(normals @ _LIGHT_DIR, 0.0, 1.0)
    emissive = [q.material.texture in EMISSIVE_TEXTURES for q in quads]
    shade[np.array(emissive, bool)] = EMISSIVE_SHADE
    return Scene(
        axis=axis,
        coord_m=np.array([q.coord_m for q in quads]),
        normal_sign=normal,
        lo_m=np.array([q.lo_m for q in quads]),
        hi_m=np.array([q.hi_m for q in quads]),
        full_height=np.array([q.full_height for q in quads]),
        texture_index=np.array([atlas.index(q.material.texture) for q in quads], np.int64),
        tile_m=np.array([q.tile_m or (q.material.tile_m,) * 2 for q in quads]),
        uv_origin_m=np.array([q.uv_origin_m for q in quads]),
        u_axis=u_axis,
        v_axis=v_axis,
        shade=shade.astype(np.float32),
        room_index=np.array([q.room_index for q in quads], np.int64),
        labels=tuple(q.label for q in quads),
        room_names=world.room_names,
        room_bounds_m=np.array([r.bounds_m for r in world.rooms]),
        atlas=atlas,
    )
