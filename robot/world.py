"""A textured indoor world for the simulated robot: rooms, doors, furniture and posters.

Frames (REP-103, metres, z up, floor at z = 0):

- The *building frame* is shared by all rooms of a world; the renderer works in it.
- Every room has its own *room frame*: origin at the room's floor corner with the smallest
  building x and y (``Room.origin_m``), axes parallel to the building axes. Furniture, posters
  and capture places are given in their room's frame; datasets record positions in it. Headings
  are therefore the same in a room frame and in the building frame.

A pose in either frame is a :class:`localizer.robot_protocol.Pose2D`; its name says which
(``pose`` of a room-frame place, ``true_pose`` of a simulated robot in the building frame).

Rooms are axis-aligned boxes with zero-thickness walls; two rooms may share a wall, and a door is
an opening in a shared wall. Wall sides are named by the outward axis direction: the ``"+x"`` wall
is at the room's largest x.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from localizer.robot_protocol import Pose2D
from robot.textures import check_texture_name

WALL_SIDES: tuple[str, str, str, str] = ("-x", "+x", "-y", "+y")


@dataclass(frozen=True)
class Material:
    """A texture tiled over a surface; one tile covers ``tile_m`` x ``tile_m`` metres."""

    texture: str
    tile_m: float = 1.0

    def __post_init__(self) -> None:
        check_texture_name(self.texture)
        if not self.tile_m > 0:
            raise ValueError(f"tile_m must be positive, got {self.tile_m}")


@dataclass(frozen=True)
class Box:
    """An occluding axis-aligned box (furniture, a pillar, an added object) in its room's frame.

    ``min_m`` and ``max_m`` are opposite corners (x, y, z) in metres. Its four sides use ``sides``
    and its top (and its bottom, if it floats) uses ``top``.
    """

    name: str
    min_m: tuple[float, float, float]
    max_m: tuple[float, float, float]
    sides: Material
    top: Material

    def __post_init__(self) -> None:
        if not all(lo < hi for lo, hi in zip(self.min_m, self.max_m, strict=True)):
            raise ValueError(f"box {self.name!r}: min_m {self.min_m} not below max_m {self.max_m}")


@dataclass(frozen=True)
class Poster:
    """A flat picture on a wall, its texture stretched over it once (not tiled).

    ``wall`` is one of ``WALL_SIDES``; ``center_m`` is the poster centre along that wall in the
    room frame (y for the x walls, x for the y walls); ``bottom_m`` its lower edge above the floor.
    """

    name: str
    wall: str
    center_m: float
    bottom_m: float
    width_m: float
    height_m: float
    texture: str

    def __post_init__(self) -> None:
        if self.wall not in WALL_SIDES:
            raise ValueError(f"poster {self.name!r}: wall must be one of {WALL_SIDES}")
        check_texture_name(self.texture)


@dataclass(frozen=True)
class Room:
    """An axis-aligned room: ``size_m`` (x, y) metres, ``height_m`` floor to ceiling.

    ``origin_m`` is the building-frame position of the room frame's origin (the room's corner of
    smallest building x and y). ``walls`` are the materials of the walls in ``WALL_SIDES`` order.
    """

    name: str
    origin_m: tuple[float, float]
    size_m: tuple[float, float]
    height_m: float
    walls: tuple[Material, Material, Material, Material]
    floor: Material
    ceiling: Material
    furniture: tuple[Box, ...] = ()
    posters: tuple[Poster, ...] = ()

    def __post_init__(self) -> None:
        if not (self.size_m[0] > 0 and self.size_m[1] > 0 and self.height_m > 0):
            raise ValueError(f"room {self.name!r}: size {self.size_m} x {self.height_m} m")

    @property
    def bounds_m(self) -> tuple[float, float, float, float]:
        """Building-frame extent ``(x_min, x_max, y_min, y_max)``."""
        x0, y0 = self.origin_m
        return x0, x0 + self.size_m[0], y0, y0 + self.size_m[1]

    def to_building(self, x_m: float, y_m: float) -> tuple[float, float]:
        """Room-frame point to building frame."""
        return self.origin_m[0] + x_m, self.origin_m[1] + y_m

    def contains(self, x_m: float, y_m: float) -> bool:
        """Whether the room-frame point lies strictly inside the room."""
        return 0 < x_m < self.size_m[0] and 0 < y_m < self.size_m[1]


@dataclass(frozen=True)
class Door:
    """An opening joining rooms ``room_a`` and ``room_b`` through the wall they share.

    ``center_m`` is the opening centre along the shared wall in the building frame (y if the wall
    is a plane x = const, x if it is a plane y = const).
    """

    room_a: str
    room_b: str
    center_m: float
    width_m: float = 0.9
    height_m: float = 2.0


@dataclass(frozen=True)
class Place:
    """A capture place: a position in the frame of room ``room``."""

    room: str
    x_m: float
    y_m: float


@dataclass(frozen=True)
class SharedWall:
    """Where two rooms touch: the plane ``axis`` (0: x, 1: y) = ``coord_m``, over [lo_m, hi_m]."""

    axis: int
    coord_m: float
    lo_m: float
    hi_m: float


def shared_wall(a: Room, b: Room, tol_m: float = 1e-6) -> SharedWall | None:
    """The wall rooms ``a`` and ``b`` share (building frame), or None if they do not touch."""
    ax0, ax1, ay0, ay1 = a.bounds_m
    bx0, bx1, by0, by1 = b.bounds_m
    along_x, along_y = (ax0, ax1, bx0, bx1), (ay0, ay1, by0, by1)
    for axis, coord_a, coord_b, (a0, a1, b0, b1) in (
        (0, ax1, bx0, along_y),
        (0, ax0, bx1, along_y),
        (1, ay1, by0, along_x),
        (1, ay0, by1, along_x),
    ):
        lo, hi = max(a0, b0), min(a1, b1)
        if abs(coord_a - coord_b) < tol_m and hi - lo > tol_m:
            return SharedWall(axis, coord_a, lo, hi)
    return None


@dataclass(frozen=True)
class World:
    """Rooms joined by doors, with the default capture-place grid spacing and clearances, and
    the default height of the robot's camera above the floor (metres)."""

    name: str
    rooms: tuple[Room, ...]
    doors: tuple[Door, ...] = ()
    place_spacing_m: float = 1.0
    wall_clearance_m: float = 0.5
    furniture_clearance_m: float = 0.3
    camera_height_m: float = 1.0

    def __post_init__(self) -> None:
        if not 0 < self.camera_height_m < min((r.height_m for r in self.rooms), default=1e9):
            raise ValueError(f"world {self.name!r}: camera_height_m {self.camera_height_m} m")
        names = [r.name for r in self.rooms]
        if len(set(names)) != len(names) or not names:
            raise ValueError(f"world {self.name!r}: room names must be unique, got {names}")
        for i, a in enumerate(self.rooms):
            for b in self.rooms[i + 1 :]:
                if _overlap(a, b):
                    raise ValueError(f"world {self.name!r}: rooms {a.name!r}, {b.name!r} overlap")
        for door in self.doors:
            wall = self.door_wall(door)
            half = door.width_m / 2
            if not wall.lo_m <= door.center_m - half < door.center_m + half <= wall.hi_m:
                raise ValueError(f"door {door} does not fit in [{wall.lo_m}, {wall.hi_m}]")
            lowest_m = min(self.room(door.room_a).height_m, self.room(door.room_b).height_m)
            if not 0 < door.height_m < lowest_m:
                raise ValueError(f"door {door}: height must be in (0, {lowest_m}) m")

    @property
    def room_names(self) -> tuple[str, ...]:
        """Names of the rooms, in order."""
        return tuple(r.name for r in self.rooms)

    def room(self, name: str) -> Room:
        """The room called ``name``; ``ValueError`` naming it if there is none."""
        for r in self.rooms:
            if r.name == name:
                return r
        raise ValueError(f"world {self.name!r} has no room {name!r}; rooms: {self.room_names}")

    def door_wall(self, door: Door) -> SharedWall:
        """The wall in which ``door`` opens; ``ValueError`` if its rooms do not touch."""
        wall = shared_wall(self.room(door.room_a), self.room(door.room_b))
        if wall is None:
            raise ValueError(f"door rooms {door.room_a!r} and {door.room_b!r} share no wall")
        return wall

    def room_at(self, x_m: float, y_m: float) -> Room | None:
        """The room containing the building-frame point, or None."""
        for r in self.rooms:
            if r.contains(x_m - r.origin_m[0], y_m - r.origin_m[1]):
                return r
        return None

    def building_pose(self, room: str, pose: Pose2D) -> Pose2D:
        """A pose in the frame of ``room`` expressed in the building frame."""
        x_m, y_m = self.room(room).to_building(pose.x_m, pose.y_m)
        return Pose2D(x_m, y_m, pose.heading_rad)


def _overlap(a: Room, b: Room) -> bool:
    ax0, ax1, ay0, ay1 = a.bounds_m
    bx0, bx1, by0, by1 = b.bounds_m
    return min(ax1, bx1) - max(ax0, bx0) > 1e-6 and min(ay1, by1) - max(ay0, by0) > 1e-6


def grid_coordinates_m(length_m: float, margin_m: float, spacing_m: float) -> np.ndarray:
    """Centred grid coordinates in [margin, length - margin] with the given spacing (metres)."""
    usable = length_m - 2 * margin_m
    if usable < 0:
        return np.zeros(0)
    n = math.floor(usable / spacing_m + 1e-9) + 1
    start = (length_m - (n - 1) * spacing_m) / 2
    return start + spacing_m * np.arange(n)


def capture_places(world: World, spacing_m: float | None = None) -> tuple[Place, ...]:
    """The capture places of every room: a grid of ``spacing_m`` (default: the world's).

    Each room's grid is centred in the room, kept ``world.wall_clearance_m`` off the walls and
    ``world.furniture_clearance_m`` off the footprint of furniture. Positions in room frames.
    """
    spacing = world.place_spacing_m if spacing_m is None else spacing_m
    if not spacing > 0:
        raise ValueError(f"spacing_m must be positive, got {spacing_m}")
    places: list[Place] = []
    for room in world.rooms:
        xs = grid_coordinates_m(room.size_m[0], world.wall_clearance_m, spacing)
        ys = grid_coordinates_m(room.size_m[1], world.wall_clearance_m, spacing)
        for y in ys:
            for x in xs:
                if not _near_furniture(room, float(x), float(y), world.furniture_clearance_m):
                    places.append(Place(room.name, round(float(x), 6), round(float(y), 6)))
    return tuple(places)


def _near_furniture(room: Room, x_m: float, y_m: float, clearance_m: float) -> bool:
    for box in room.furniture:
        if (
            box.min_m[0] - clearance_m <= x_m <= box.max_m[0] + clearance_m
            and box.min_m[1] - clearance_m <= y_m <= box.max_m[1] + clearance_m
        ):
            return True
    return False
