"""A simulated robot in a rendered world: it captures panoramas at its true pose, turns and drives
with Gaussian motion noise, stops at walls and furniture, and keeps odometry of what it was told.

Frames (REP-103, metres, radians): the *true pose* is in the world's building frame (see
:mod:`robot.world`); the *odometry frame* starts at the robot's starting pose (odometry (0, 0, 0))
and integrates the commanded motion, so it drifts from the truth when there is motion noise.

Body: a disc of ``radius_m`` around the camera axis. It may not come closer than ``radius_m`` to
a wall (doors are openings in the shared walls, so the robot passes through a door wider than its
diameter) or to the floor footprint of any box (furniture, and the objects a capture condition
adds: the camera is about 1 m high, so the robot does not fit under a table). A drive stops at the
last free position along its straight path (checked every ``PATH_STEP_M``) and reports ``bumped``.

Captures are rendered like ``toploc dataset render`` renders map panoramas (same default
:class:`~robot.render.PanoramaCamera`: 1024 x 192 px, square pixels, camera at the world's
``camera_height_m`` above the floor), at the true pose, under a capture condition, with a fresh
sensor-noise seed per capture.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from homing.bearings import wrap_angle_rad
from localizer.robot_protocol import Capture, MoveResult, Pose2D
from robot.conditions import Condition, get_condition, world_under
from robot.render import PanoramaCamera, render_panorama
from robot.scene import build_scene
from robot.world import WALL_SIDES, Room, World
from robot.worlds import make_world

PATH_STEP_M = 0.01
LINEAR_SPEED_M_S = 0.3
TURN_SPEED_RAD_S = math.radians(60.0)
CAPTURE_TIME_S = 1.0


@dataclass(frozen=True)
class MotionNoise:
    """Gaussian motion noise: standard deviations as fractions of the commanded distance and turn.

    A move of ``forward_m`` really drives ``forward_m * (1 + N(0, forward_frac))``; a turn of
    ``turn_rad`` really turns ``turn_rad * (1 + N(0, turn_frac))``. Zero: exact motion.
    """

    forward_frac: float = 0.0
    turn_frac: float = 0.0

    def __post_init__(self) -> None:
        if not (self.forward_frac >= 0 and self.turn_frac >= 0):
            raise ValueError(f"motion noise fractions must be >= 0, got {self}")


def wall_segments(world: World) -> np.ndarray:
    """(n, 4) building-frame wall segments ``x0, y0, x1, y1``: every room side minus its doors."""
    segments: list[tuple[float, float, float, float]] = []
    for room in world.rooms:
        x0, x1, y0, y1 = room.bounds_m
        for side in WALL_SIDES:
            axis = 0 if side[1] == "x" else 1
            coord = (x0, x1)[side[0] == "+"] if axis == 0 else (y0, y1)[side[0] == "+"]
            lo, hi = (y0, y1) if axis == 0 else (x0, x1)
            for a, b in _subtract(lo, hi, _door_gaps(world, room, axis, coord)):
                segments.append((coord, a, coord, b) if axis == 0 else (a, coord, b, coord))
    return np.array(segments, dtype=float).reshape(-1, 4)


def _door_gaps(world: World, room: Room, axis: int, coord_m: float) -> list[tuple[float, float]]:
    """Door openings (building-frame intervals along the wall) in ``room``'s wall at ``coord_m``."""
    gaps = []
    for door in world.doors:
        if room.name not in (door.room_a, door.room_b):
            continue
        wall = world.door_wall(door)
        if wall.axis == axis and abs(wall.coord_m - coord_m) < 1e-6:
            gaps.append((door.center_m - door.width_m / 2, door.center_m + door.width_m / 2))
    return sorted(gaps)


def _subtract(lo: float, hi: float, gaps: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """The interval [lo, hi] minus the sorted ``gaps``."""
    pieces, start = [], lo
    for a, b in gaps:
        if a > start:
            pieces.append((start, min(a, hi)))
        start = max(start, b)
    if start < hi:
        pieces.append((start, hi))
    return pieces


def box_footprints(world: World) -> np.ndarray:
    """(m, 4) building-frame floor footprints ``x_min, y_min, x_max, y_max`` of every box."""
    rows = [
        (
            *room.to_building(box.min_m[0], box.min_m[1]),
            *room.to_building(box.max_m[0], box.max_m[1]),
        )
        for room in world.rooms
        for box in room.furniture
    ]
    return np.array(rows, dtype=float).reshape(-1, 4)


def clearance_m(points_xy: np.ndarray, segments: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """(k,) distance in metres from each building-frame point (k, 2) to the nearest wall segment
    or box footprint (0 inside a footprint); inf if there are neither."""
    p = np.atleast_2d(np.asarray(points_xy, dtype=float))
    best = np.full(len(p), np.inf)
    if len(segments):
        a, b = segments[:, :2], segments[:, 2:]
        ab = b - a
        length2 = np.maximum((ab**2).sum(axis=1), 1e-18)
        t = np.clip(((p[:, None, :] - a) * ab).sum(axis=2) / length2, 0.0, 1.0)
        nearest = a + t[..., None] * ab
        best = np.minimum(best, np.linalg.norm(p[:, None, :] - nearest, axis=2).min(axis=1))
    if len(boxes):
        dx = np.maximum(np.maximum(boxes[:, 0] - p[:, :1], p[:, :1] - boxes[:, 2]), 0.0)
        dy = np.maximum(np.maximum(boxes[:, 1] - p[:, 1:], p[:, 1:] - boxes[:, 3]), 0.0)
        best = np.minimum(best, np.hypot(dx, dy).min(axis=1))
    return best


@dataclass(frozen=True)
class Obstacles:
    """What stops a disc robot of ``radius_m`` in ``world`` (building frame, metres)."""

    world: World
    radius_m: float
    segments: np.ndarray  # (n, 4) wall segments, see wall_segments
    boxes: np.ndarray  # (m, 4) box footprints, see box_footprints

    @classmethod
    def of(cls, world: World, radius_m: float) -> Obstacles:
        """The walls (doors left open) and box footprints of ``world``."""
        if not radius_m > 0:
            raise ValueError(f"radius_m must be positive, got {radius_m}")
        return cls(world, radius_m, wall_segments(world), box_footprints(world))

    def free(self, points_xy: np.ndarray) -> np.ndarray:
        """(k,) bool: whether the disc fits at each point (k, 2): inside a room (or in a door
        opening) and at least ``radius_m`` from walls and box footprints."""
        p = np.atleast_2d(np.asarray(points_xy, dtype=float))
        clear = clearance_m(p, self.segments, self.boxes) >= self.radius_m
        inside = np.array(
            [self.world.room_at(x, y) is not None or self._on_door_line(x, y) for x, y in p]
        )
        return clear & inside

    def fits_in(self, room: str, x_m: float, y_m: float) -> bool:
        """Whether the disc fits at ``(x_m, y_m)`` inside ``room`` (not in a door opening)."""
        found = self.world.room_at(x_m, y_m)
        return (
            found is not None and found.name == room and bool(self.free(np.array([[x_m, y_m]]))[0])
        )

    def _on_door_line(self, x_m: float, y_m: float) -> bool:
        for door in self.world.doors:
            wall = self.world.door_wall(door)
            across, along = (x_m, y_m) if wall.axis == 0 else (y_m, x_m)
            if abs(across - wall.coord_m) < 1e-9 and abs(along - door.center_m) < door.width_m / 2:
                return True
        return False

    def reach_m(self, pose: Pose2D, heading_rad: float, distance_m: float) -> tuple[float, bool]:
        """Signed distance a disc at ``pose`` can drive along ``heading_rad``, up to
        ``distance_m`` (checked every ``PATH_STEP_M``), and whether contact stopped it."""
        n = max(1, math.ceil(abs(distance_m) / PATH_STEP_M))
        s = np.linspace(0.0, distance_m, n + 1)[1:]
        points = np.column_stack(
            [pose.x_m + s * math.cos(heading_rad), pose.y_m + s * math.sin(heading_rad)]
        )
        free = self.free(points)
        if free.all():
            return float(distance_m), False
        first_blocked = int(np.argmin(free))
        return (float(s[first_blocked - 1]) if first_blocked > 0 else 0.0), True


def random_free_pose(
    obstacles: Obstacles, room: str, rng: np.random.Generator, max_tries: int = 10_000
) -> Pose2D:
    """A uniform random position where the disc fits inside ``room`` (building frame) with a
    uniform random heading; ``ValueError`` naming the room if ``max_tries`` draws all fail."""
    x0, x1, y0, y1 = obstacles.world.room(room).bounds_m
    for _ in range(max_tries):
        x, y = float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1))
        heading = float(rng.uniform(-math.pi, math.pi))
        if obstacles.fits_in(room, x, y):
            return Pose2D(x, y, heading)
    raise ValueError(f"no free position for a {obstacles.radius_m} m robot in room {room!r}")


class SimulatedRobot:
    """A :class:`localizer.robot_protocol.Robot` in a rendered world (see the module docstring).

    ``world`` is the world without the condition's objects; they are added here (seeded by
    ``seed``, as ``toploc dataset render`` does) and block motion. ``pose`` is the true starting
    pose in the building frame. ``seed`` also seeds the motion noise and, with the capture count,
    each capture's sensor noise. ``grey`` captures H x W grey images, otherwise H x W x 3 BGR.
    Raises ``ValueError`` if the starting pose is outside every room or collides.
    """

    def __init__(
        self,
        world: World,
        pose: Pose2D,
        *,
        camera: PanoramaCamera | None = None,
        condition: str | Condition = "default",
        seed: int = 0,
        noise: MotionNoise | None = None,
        radius_m: float = 0.2,
        grey: bool = False,
    ) -> None:
        self.condition = get_condition(condition) if isinstance(condition, str) else condition
        self.world = world_under(world, self.condition, seed)
        self.obstacles = Obstacles.of(self.world, radius_m)
        self.camera = camera or PanoramaCamera(height_m=world.camera_height_m)
        self.noise = noise or MotionNoise()
        self.grey = grey
        self.seed = seed
        if not self.obstacles.free(np.array([[pose.x_m, pose.y_m]]))[0]:
            raise ValueError(
                f"starting pose ({pose.x_m}, {pose.y_m}) m is outside world {world.name!r} or "
                f"within {radius_m} m of a wall or furniture"
            )
        self._scene = build_scene(self.world)
        self._rng = np.random.default_rng([seed, 11])
        heading_rad = float(wrap_angle_rad(pose.heading_rad))
        self._pose = Pose2D(float(pose.x_m), float(pose.y_m), heading_rad)
        self._odom = Pose2D(0.0, 0.0, 0.0)
        self._captures = 0
        self._clock_s = 0.0
        self.distance_driven_m = 0.0
        """True distance driven so far (metres along the path; bumps stop it)."""

    @classmethod
    def kidnapped(
        cls,
        world: World,
        room: str,
        seed: int,
        condition: str | Condition = "default",
        radius_m: float = 0.2,
        **kwargs: Any,
    ) -> SimulatedRobot:
        """A robot put at a seeded uniform random free position in ``room`` with a uniform
        random heading; the other arguments go to the constructor. ``ValueError`` if the room
        is unknown or has no room for the robot."""
        cond = get_condition(condition) if isinstance(condition, str) else condition
        obstacles = Obstacles.of(world_under(world, cond, seed), radius_m)
        pose = random_free_pose(obstacles, room, np.random.default_rng([seed, 13]))
        return cls(world, pose, condition=cond, seed=seed, radius_m=radius_m, **kwargs)

    @classmethod
    def in_world(
        cls, world_name: str, pose: Pose2D, world_seed: int = 0, **kwargs: Any
    ) -> SimulatedRobot:
        """A robot in the preset world ``world_name`` built from ``world_seed`` (use the seed the
        map dataset was rendered with); ``pose`` in the building frame."""
        return cls(make_world(world_name, world_seed), pose, **kwargs)

    # -- ground truth (not part of the Robot protocol) --------------------------------------

    @property
    def true_pose(self) -> Pose2D:
        """The true pose in the building frame."""
        return self._pose

    @property
    def radius_m(self) -> float:
        """Radius of the robot's disc in metres."""
        return self.obstacles.radius_m

    def true_room(self) -> str | None:
        """Name of the room the robot is really in, or None (exactly on a door's threshold)."""
        room = self.world.room_at(self._pose.x_m, self._pose.y_m)
        return None if room is None else room.name

    def carry(self, pose: Pose2D) -> None:
        """Put the robot at ``pose`` (building frame) without its odometry knowing: a
        kidnapping. ``ValueError`` if ``pose`` is outside every room or collides."""
        if not self.obstacles.free(np.array([[pose.x_m, pose.y_m]]))[0]:
            raise ValueError(f"cannot carry the robot to ({pose.x_m}, {pose.y_m}) m: not free")
        self._pose = Pose2D(
            float(pose.x_m), float(pose.y_m), float(wrap_angle_rad(pose.heading_rad))
        )

    # -- the Robot protocol -------------------------------------------------------------------

    def capture(self) -> Capture:
        """Render the panorama at the true pose (sensor noise seeded by seed and capture count)."""
        image = render_panorama(
            self._scene,
            self._pose,
            self.camera,
            self.condition,
            seed=(self.seed, 17, self._captures),
            grey=self.grey,
        )
        if not self.grey:
            image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        self._captures += 1
        self._clock_s += CAPTURE_TIME_S
        return Capture(image, self._clock_s, f"sim:{self.world.name}")

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        """Turn by ``turn_rad`` then drive ``forward_m`` (both noisy); stop before a collision.

        The result and the odometry report the commanded turn and the commanded distance, cut
        short by the fraction of the real drive completed when bumped (what wheel encoders
        that do not see the noise would report).
        """
        if not (math.isfinite(turn_rad) and math.isfinite(forward_m)):
            raise ValueError(
                f"move needs finite turn_rad and forward_m, got {turn_rad}, {forward_m}"
            )
        real_turn = turn_rad * (1.0 + self._rng.normal(0.0, self.noise.turn_frac))
        real_forward = forward_m * (1.0 + self._rng.normal(0.0, self.noise.forward_frac))
        heading = float(wrap_angle_rad(self._pose.heading_rad + real_turn))
        driven, bumped = self.obstacles.reach_m(self._pose, heading, real_forward)
        self._pose = Pose2D(
            float(self._pose.x_m + driven * math.cos(heading)),
            float(self._pose.y_m + driven * math.sin(heading)),
            heading,
        )
        self.distance_driven_m += abs(driven)
        reported = forward_m * (driven / real_forward) if real_forward != 0 else forward_m
        odom_heading = float(wrap_angle_rad(self._odom.heading_rad + turn_rad))
        self._odom = Pose2D(
            self._odom.x_m + reported * math.cos(odom_heading),
            self._odom.y_m + reported * math.sin(odom_heading),
            odom_heading,
        )
        self._clock_s += abs(real_turn) / TURN_SPEED_RAD_S + abs(driven) / LINEAR_SPEED_M_S
        return MoveResult(turned_rad=turn_rad, moved_m=reported, bumped=bumped)

    def odometry(self) -> Pose2D:
        """Dead-reckoned pose in the odometry frame (the commanded motion integrated)."""
        return self._odom

    def stop(self) -> None:
        """Nothing to stop: a simulated move is done at once (in simulated time)."""
