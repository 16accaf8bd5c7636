"""Capture conditions, in the spirit of Vardy's image sets: lighting, sensor noise, added objects.

A :class:`Condition` changes an image photometrically (gain and gamma of the light, Gaussian
sensor noise) and may add objects to every room (boxes standing against the walls, kept clear of
doors, furniture and the capture places). Conditions are named; ``CONDITIONS`` lists them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from robot.textures import PHOTO_TEXTURES
from robot.world import WALL_SIDES, Box, Material, Room, World


@dataclass(frozen=True)
class Condition:
    """How a capture differs from the default.

    Output grey level ``= clip(gain * 255 * (radiance / 255) ** gamma + noise)``, with noise
    Gaussian of ``noise_std`` grey levels; ``objects_per_room`` boxes are added to every room.
    """

    name: str
    gain: float = 1.0
    gamma: float = 1.0
    noise_std: float = 0.0
    objects_per_room: int = 0
    description: str = ""

    def __post_init__(self) -> None:
        if not (self.gain > 0 and self.gamma > 0 and self.noise_std >= 0):
            raise ValueError(f"condition {self.name!r}: gain and gamma > 0, noise_std >= 0")
        if self.objects_per_room < 0:
            raise ValueError(f"condition {self.name!r}: objects_per_room must be >= 0")


DEFAULT_CONDITION = Condition("default", description="the reference lighting, no noise")
CONDITIONS: dict[str, Condition] = {
    c.name: c
    for c in (
        DEFAULT_CONDITION,
        Condition("dim", gain=0.45, gamma=1.3, description="lights dimmed (evening)"),
        Condition("bright", gain=1.4, gamma=0.8, description="strong light, highlights clip"),
        Condition("noisy", noise_std=12.0, description="sensor noise, 12 grey levels std"),
        Condition("objects", objects_per_room=4, description="boxes added along the walls"),
        Condition(
            "dim_noisy", gain=0.5, gamma=1.2, noise_std=8.0, description="dim light, noisy sensor"
        ),
    )
}


def get_condition(name: str) -> Condition:
    """The condition called ``name``; ``ValueError`` naming it and the known ones otherwise."""
    try:
        return CONDITIONS[name]
    except KeyError:
        known = ", ".join(CONDITIONS)
        raise ValueError(f"unknown condition {name!r}; known conditions: {known}") from None


def apply_photometric(
    radiance: np.ndarray, condition: Condition, rng: np.random.Generator
) -> np.ndarray:
    """Apply gain, gamma and noise to float radiance in grey levels (0..255); returns uint8."""
    image = np.clip(radiance, 0.0, 255.0) / 255.0
    if condition.gamma != 1.0:
        image = image**condition.gamma
    image = image * (255.0 * condition.gain)
    if condition.noise_std > 0:
        image = image + rng.normal(0.0, condition.noise_std, image.shape).astype(np.float32)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def world_under(world: World, condition: Condition, seed: int = 0) -> World:
    """``world`` with the objects ``condition`` adds (the same world if it adds none)."""
    if condition.objects_per_room == 0:
        return world
    return add_objects(world, condition.objects_per_room, seed)


def add_objects(world: World, per_room: int, seed: int = 0) -> World:
    """Add up to ``per_room`` seeded boxes against the walls of every room.

    Boxes are at most ``world.wall_clearance_m - 0.1`` m deep, so capture places stay free; they
    keep 0.3 m from door openings and 0.1 m from other furniture. Rooms too crowded get fewer.
    """
    rooms = []
    for i, room in enumerate(world.rooms):
        rng = np.random.default_rng([seed, i])
        boxes = list(room.furniture)
        for k in range(per_room):
            box = _place_object(world, room, boxes, rng, f"object{k}")
            if box is not None:
                boxes.append(box)
        rooms.append(dataclasses.replace(room, furniture=tuple(boxes)))
    return dataclasses.replace(world, rooms=tuple(rooms))


def _place_object(
    world: World, room: Room, boxes: list[Box], rng: np.random.Generator, name: str
) -> Box | None:
    """A random box against a wall of ``room`` overlapping nothing, or None after 50 tries."""
    max_depth = world.wall_clearance_m - 0.1
    if max_depth < 0.1:
        return None
    for _ in range(50):
        side = WALL_SIDES[int(rng.integers(4))]
        axis = 0 if side[1] == "x" else 1
        depth = rng.uniform(0.1, max_depth)
        width, height = rng.uniform(0.3, 0.8), rng.uniform(0.3, 1.3)
        length = room.size_m[1 - axis]
        if length < width + 0.2:
            continue
        along = rng.uniform(0.1, length - width - 0.1)
        near = 0.01 if side[0] == "-" else room.size_m[axis] - 0.01 - depth
        lo = [0.0, 0.0, 0.0]
        lo[axis], lo[1 - axis] = near, along
        size = [0.0, 0.0, height]
        size[axis], size[1 - axis] = depth, width
        hi = (lo[0] + size[0], lo[1] + size[1], height)
        if _blocked(world, room, boxes, (lo[0], lo[1], hi[0], hi[1])):
            continue
        sides, top = rng.choice(PHOTO_TEXTURES, size=2)
        tile_m = float(rng.uniform(0.3, 0.8))
        return Box(name, (lo[0], lo[1], 0.0), hi, Material(str(sides), tile_m), Material(str(top)))
    return None


def _blocked(
    world: World, room: Room, boxes: list[Box], footprint: tuple[float, float, float, float]
) -> bool:
    """Whether a room-frame footprint (x0, y0, x1, y1) hits furniture or a door's approach."""
    x0, y0, x1, y1 = footprint
    for box in boxes:
        overlap_x = x0 < box.max_m[0] + 0.1 and box.min_m[0] - 0.1 < x1
        if overlap_x and y0 < box.max_m[1] + 0.1 and box.min_m[1] - 0.1 < y1:
            return True
    ox, oy = room.origin_m
    for door in world.doors:
        if room.name not in (door.room_a, door.room_b):
            continue
        wall = world.door_wall(door)
        lo = door.center_m - door.width_m / 2 - 0.3 - (oy if wall.axis == 0 else ox)
        hi = lo + door.width_m + 0.6
        a0, a1 = (y0, y1) if wall.axis == 0 else (x0, x1)
        if a0 < hi and lo < a1:
            return True
    return False
