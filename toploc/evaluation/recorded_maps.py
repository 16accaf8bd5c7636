"""Maps recorded the way a user records them (issue 19, section 1), with the simulated robot.

A user follows the README's loop: drive the robot into a room, ``toploc map record``, turn and
drive a little, record again, a few places per room; then the next room. :func:`record_map`
does that in a rendered world, in process: per room the robot starts at a seeded random free
pose (where the user drove it in), and between two records it turns by a random angle and
drives 0.5–1.5 m (a drive that would bump or leave the room is drawn again, as a user steers
clear). Each place is stored as the map node's ``map/add`` stores it (the same extraction, the
pose the robot's odometry reports: its frame starts at the room's first record), the room graph
gets the world's doors (``--connect-room``), and the likelihood is calibrated on the result as
the service does after adds.

Unlike a batch-rendered map (a place every metre on a grid), the look-alike rooms' places are
then at different spots of their own frames: between twins, the inlier count says which room
has a stored place nearer the robot, not which room it is in. That is the map the belief must
stay honest on.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from homing.bearings import wrap_angle_rad
from localizer.localizer import to_grey
from localizer.robot_protocol import Pose2D
from mapdb.database import MapDatabase
from mapdb.records import Leg, NewPlace
from robot.render import PanoramaCamera
from robot.sim_robot import Obstacles, SimulatedRobot, random_free_pose
from robot.world import Door, World
from toploc.extraction import extract_image, map_overrides
from toploc.maps import calibrate_map

STEP_M = (0.5, 1.5)
"""How far the robot drives between two records of one room (uniform, metres)."""
MAX_DRAWS = 200
"""Turn-and-drive draws tried before a room is said to have no room for another step."""


@dataclass(frozen=True)
class RecordedPlace:
    """One recorded place: its id in the map, its room and where it really was (building frame,
    ground truth the map does not hold)."""

    place_id: int
    room: str
    true_pose: Pose2D


def _step(
    obstacles: Obstacles, room: str, pose: Pose2D, rng: np.random.Generator
) -> tuple[float, float]:
    """A turn (rad) and a drive (m) from ``pose`` that stays inside ``room`` without bumping."""
    world = obstacles.world
    for _ in range(MAX_DRAWS):
        turn_rad = float(rng.uniform(-math.pi, math.pi))
        forward_m = float(rng.uniform(*STEP_M))
        heading_rad = pose.heading_rad + turn_rad
        _, bumped = obstacles.reach_m(pose, heading_rad, forward_m)
        x_m = pose.x_m + forward_m * math.cos(heading_rad)
        y_m = pose.y_m + forward_m * math.sin(heading_rad)
        inside = world.room_at(x_m, y_m)
        if not bumped and inside is not None and inside.name == room:
            return turn_rad, forward_m
    raise ValueError(f"room {room!r}: no drive of {STEP_M} m stays inside it without bumping")


def record_room(
    world: World,
    room: str,
    places: int,
    seed: int,
    db_path: Path,
    detectors: Sequence[str],
    camera: PanoramaCamera | None = None,
) -> list[RecordedPlace]:
    """Record ``places`` panoramas in ``room`` into the map at ``db_path`` (created if absent),
    a random turn and drive between two (seeded by ``seed``), with ``camera`` (default: the
    robot node's sim camera, 1024 x 192); returns what was recorded."""
    rng = np.random.default_rng([seed, 19])
    start = random_free_pose(Obstacles.of(world, 0.2), room, rng)
    robot = SimulatedRobot(world, start, seed=seed, grey=True, camera=camera)
    recorded: list[RecordedPlace] = []
    for k in range(places):
        if k:
            turn_rad, forward_m = _step(robot.obstacles, room, robot.true_pose, rng)
            robot.move(turn_rad, forward_m)
        recorded.append(_record(robot, world, room, f"#{k}", db_path, detectors))
    return recorded


def _record(
    robot: SimulatedRobot,
    world: World,
    room: str,
    label: str,
    db_path: Path,
    detectors: Sequence[str],
    leg: Leg | None = None,
) -> RecordedPlace:
    """Capture and add a place of ``room`` to the map at ``db_path`` (created if absent), at
    the robot's odometry pose, with the ``leg`` it was driven on, as ``map/add`` does."""
    image = to_grey(robot.capture().image)
    odometry = robot.odometry()
    sha = hashlib.sha256(image.tobytes()).hexdigest()
    place = NewPlace(
        room=room,
        image_sha256=sha,
        source=f"recorded {world.name} {room} {label} sha256:{sha[:12]}",
        x_m=odometry.x_m,
        y_m=odometry.y_m,
        heading_deg=math.degrees(odometry.heading_rad),
        leg=leg,
    )
    with MapDatabase.open(db_path, create=True) as map_db:
        fingerprints = extract_image(image, tuple(detectors), "auto", map_overrides(map_db))
        place_id = map_db.add_place(place, fingerprints)
    return RecordedPlace(place_id, room, robot.true_pose)


DOOR_APPROACH_M = 0.6
"""How far from a door's line the recording drive stops before crossing it (metres)."""


@dataclass(frozen=True)
class DrivenPlace:
    """A place recorded on one continuous drive: what :class:`RecordedPlace` says, the
    odometry pose it was recorded at and the leg the map stores for it (None for the first)."""

    recorded: RecordedPlace
    odometry: Pose2D
    leg: Leg | None


def door_points(world: World, door: Door, room: str) -> tuple[tuple[float, float], ...]:
    """Two building-frame points on the door's centre line, :data:`DOOR_APPROACH_M` from the
    wall: the one in ``room``, then the one in the other room."""
    wall = world.door_wall(door)
    lo_x, _, lo_y, _ = world.room(room).bounds_m
    inside_low = (lo_x if wall.axis == 0 else lo_y) < wall.coord_m - 1e-6
    sign = -1.0 if inside_low else 1.0
    near, far = wall.coord_m + sign * DOOR_APPROACH_M, wall.coord_m - sign * DOOR_APPROACH_M
    if wall.axis == 0:
        return (near, door.center_m), (far, door.center_m)
    return (door.center_m, near), (door.center_m, far)


def _segment_free(obstacles: Obstacles, a: tuple[float, float], b: tuple[float, float]) -> bool:
    length = math.hypot(b[0] - a[0], b[1] - a[1])
    heading = math.atan2(b[1] - a[1], b[0] - a[0])
    _, bumped = obstacles.reach_m(Pose2D(a[0], a[1], 0.0), heading, length)
    return not bumped


def plan_in_room(
    obstacles: Obstacles,
    room: str,
    start: tuple[float, float],
    goal: tuple[float, float],
    rng: np.random.Generator,
) -> list[tuple[float, float]]:
    """Waypoints (building frame) from ``start`` to ``goal`` within ``room``: straight if
    nothing is in the way, else through the one free point of ``room`` (of 200 seeded draws)
    that gives the shortest two-segment path. ``ValueError`` naming the room if none does."""
    if _segment_free(obstacles, start, goal):
        return [goal]
    best: tuple[float, tuple[float, float]] | None = None
    for _ in range(MAX_DRAWS):
        mid = random_free_pose(obstacles, room, rng)
        via = (mid.x_m, mid.y_m)
        if _segment_free(obstacles, start, via) and _segment_free(obstacles, via, goal):
            length = math.dist(start, via) + math.dist(via, goal)
            if best is None or length < best[0]:
                best = (length, via)
    if best is None:
        raise ValueError(f"room {room!r}: no path from {start} to {goal}")
    return [best[1], goal]


def _drive_to(robot: SimulatedRobot, goal: tuple[float, float]) -> Pose2D:
    """Turn toward ``goal`` and drive there (the user steers by sight: from the true pose),
    correcting once if the motion noise left it more than 5 cm off; the odometry after."""
    for _ in range(2):
        pose = robot.true_pose
        dx, dy = goal[0] - pose.x_m, goal[1] - pose.y_m
        if math.hypot(dx, dy) < 0.05:
            break
        turn_rad = float(wrap_angle_rad(math.atan2(dy, dx) - pose.heading_rad))
        robot.move(turn_rad, math.hypot(dx, dy))
    return robot.odometry()


def room_walk(world: World, rooms: Sequence[str], first: str) -> list[tuple[str, Door | None]]:
    """The rooms in the order a depth-first drive through the doors visits them from
    ``first`` (a room visited again on the way back is listed again), each with the door the
    drive came in by (None for ``first``); only doors between ``rooms`` are used."""
    walk: list[tuple[str, Door | None]] = [(first, None)]
    seen = {first}

    def visit(room: str) -> None:
        for door in world.doors:
            if room not in (door.room_a, door.room_b):
                continue
            other = door.room_b if door.room_a == room else door.room_a
            if other in seen or other not in rooms:
                continue
            seen.add(other)
            walk.append((other, door))
            visit(other)
            walk.append((room, door))

    visit(first)
    return walk


def record_drive(
    world: World,
    places_per_room: int,
    seed: int,
    db_path: Path,
    rooms: Sequence[str] | None = None,
    detectors: Sequence[str] = ("sift",),
    camera: PanoramaCamera | None = None,
) -> list[DrivenPlace]:
    """Record ``places_per_room`` places in each of ``rooms`` on one continuous drive, as a
    user does who drives the robot from room to room: the robot starts at a seeded random free
    pose of the first room and drives through the doors, depth first; in each room it first
    enters, it records as :func:`record_room` does (a random turn and drive between two). The
    odometry never restarts, so all places share one frame, and each place but the first is
    stored with its :class:`~mapdb.records.Leg` (the odometry positions driven since the
    previous one), as ``toploc map record`` stores a drive. Stores places only (no edges, no
    calibration)."""
    chosen = tuple(rooms) if rooms is not None else tuple(r.name for r in world.rooms)
    rng = np.random.default_rng([seed, 29])
    obstacles = Obstacles.of(world, 0.2)
    start = random_free_pose(obstacles, chosen[0], rng)
    robot = SimulatedRobot(world, start, seed=seed, grey=True, camera=camera)
    recorded: list[DrivenPlace] = []
    via: list[tuple[float, float]] = []
    done: set[str] = set()
    for room, door in room_walk(world, chosen, chosen[0]):
        if door is not None:
            came_from = door.room_a if door.room_b == room else door.room_b
            near, far = door_points(world, door, came_from)
            here = (robot.true_pose.x_m, robot.true_pose.y_m)
            for point in [*plan_in_room(obstacles, came_from, here, near, rng), far]:
                reached = _drive_to(robot, point)
                via.append((reached.x_m, reached.y_m))
        if room in done:
            continue
        done.add(room)
        for k in range(places_per_room):
            if k or door is not None:
                turn_rad, forward_m = _step(obstacles, room, robot.true_pose, rng)
                robot.move(turn_rad, forward_m)
            leg = None if not recorded else Leg(recorded[-1].recorded.place_id, tuple(via))
            place = _record(robot, world, room, f"#{k}", db_path, detectors, leg)
            recorded.append(DrivenPlace(place, robot.odometry(), leg))
            via = []
    return recorded


def _miss(
    obstacles: Obstacles,
    room: str,
    spot_xy_m: tuple[float, float],
    shift_xy_m: tuple[float, float],
    offset_m: float,
    rng: np.random.Generator,
) -> tuple[float, float]:
    """``shift_xy_m`` (from a spot of the first twin to the same spot of ``room``, building
    frame, m) plus ``offset_m`` in a random direction, where the robot fits inside ``room``
    (without the offset when no draw fits)."""
    for _ in range(MAX_DRAWS if offset_m > 0 else 0):
        angle_rad = float(rng.uniform(-math.pi, math.pi))
        dx = shift_xy_m[0] + offset_m * math.cos(angle_rad)
        dy = shift_xy_m[1] + offset_m * math.sin(angle_rad)
        if obstacles.fits_in(room, spot_xy_m[0] + dx, spot_xy_m[1] + dy):
            return dx, dy
    return shift_xy_m


def record_counterparts(
    world: World,
    pairs: Sequence[tuple[str, str]],
    seed: int,
    db_path: Path,
    detectors: Sequence[str] = ("sift",),
    camera: PanoramaCamera | None = None,
    spots: int = 2,
    offset_m: float = 0.0,
) -> list[RecordedPlace]:
    """Follow ``toploc map info``'s advice for look-alike rooms without counterparts: record
    ``spots`` more places in each room of each pair, at the same spots of their frames (seeded
    random free spots of the first room, the same room-frame positions in the second: the
    twins' frames are identical), with no pose (the user carried the robot there); then
    calibrate again. ``offset_m``: the second room's place stands this far from the spot, in a
    seeded random direction (a user placing the robot by eye misses it by a few decimetres)."""
    rng = np.random.default_rng([seed, 23])
    obstacles = Obstacles.of(world, 0.2)
    recorded: list[RecordedPlace] = []
    for first, second in [pair for pair in pairs for _ in range(spots)]:
        spot = random_free_pose(obstacles, first, rng)
        (x0, y0), (x1, y1) = world.room(first).origin_m, world.room(second).origin_m
        spot_xy_m, shift_xy_m = (spot.x_m, spot.y_m), (x1 - x0, y1 - y0)
        miss = _miss(obstacles, second, spot_xy_m, shift_xy_m, offset_m, rng)
        for room, (dx, dy) in ((first, (0.0, 0.0)), (second, miss)):
            heading_rad = float(rng.uniform(-math.pi, math.pi))
            pose = Pose2D(spot.x_m + dx, spot.y_m + dy, heading_rad)
            robot = SimulatedRobot(world, pose, seed=seed, grey=True, camera=camera)
            image = to_grey(robot.capture().image)
            sha = hashlib.sha256(image.tobytes()).hexdigest()
            place = NewPlace(
                room, sha, f"recorded {world.name} {room} counterpart sha256:{sha[:12]}"
            )
            with MapDatabase.open(db_path, create=False) as map_db:
                fingerprints = extract_image(image, tuple(detectors), "auto", map_overrides(map_db))
                place_id = map_db.add_place(place, fingerprints)
            recorded.append(RecordedPlace(place_id, room, pose))
    for detector in detectors:
        calibrate_map(db_path, detector)
    return recorded


def record_map(
    world: World,
    places_per_room: int,
    seed: int,
    db_path: Path,
    rooms: Sequence[str] | None = None,
    detectors: Sequence[str] = ("sift",),
    progress: bool = False,
    camera: PanoramaCamera | None = None,
    drive: bool = False,
) -> list[RecordedPlace]:
    """Record ``places_per_room`` places in each of ``rooms`` (default: every room of ``world``)
    into a new map at ``db_path``, connect the rooms the world's doors join, and calibrate the
    likelihood of each detector. ``drive``: on one continuous drive through the doors
    (:func:`record_drive`, one odometry frame), else room by room (:func:`record_room`, the
    odometry restarted in each). ``FileExistsError`` if ``db_path`` exists: a recording starts
    from an empty map."""
    if places_per_room < 1:
        raise ValueError(f"places_per_room must be >= 1, got {places_per_room}")
    if db_path.exists():
        raise FileExistsError(f"{db_path} exists: a recorded map starts from an empty file")
    chosen = tuple(rooms) if rooms is not None else tuple(r.name for r in world.rooms)
    unknown = set(chosen) - {r.name for r in world.rooms}
    if unknown:
        raise ValueError(f"world {world.name!r} has no room {sorted(unknown)}")
    recorded: list[RecordedPlace] = []
    if drive:
        driven = record_drive(world, places_per_room, seed, db_path, chosen, detectors, camera)
        recorded = [place.recorded for place in driven]
    else:
        bar = tqdm(chosen, desc=f"record {world.name} x{places_per_room}", disable=not progress)
        for i, room in enumerate(bar):
            recorded += record_room(
                world, room, places_per_room, seed * 1000 + i, db_path, detectors, camera
            )
    with MapDatabase.open(db_path, create=False) as map_db:
        for door in world.doors:
            if door.room_a in chosen and door.room_b in chosen:
                map_db.connect_rooms(door.room_a, door.room_b)
    for detector in detectors:
        calibrate_map(db_path, detector)
    return recorded
