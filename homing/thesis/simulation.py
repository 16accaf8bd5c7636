"""The thesis's homing simulation (Goldhoorn 2008, chapter 4 and appendix A), vectorised.

The world is a box centred on the origin with walls of ``wall_height_m`` whose features are
points spread uniformly over the walls that are present (table 4.2), each pushed off its wall
plane by up to ``roughness_m``. The thesis's xz-plane is our xy-plane (REP-103, z up); the
camera is ``camera_height_m`` above the floor. Walls are numbered 1: y = -Ly/2, 2: x = +Lx/2,
3: y = +Ly/2, 4: x = -Lx/2, so that world 3's two walls both run along x and world 2 has one
wall along each axis, as section 4.3.7 describes.

A projection (``AcquireCylinder``) sees a feature when it is at least ``min_range_m`` away and
lands on the image plane: its height on the unit cylinder, ``dz / horizontal range``, is within
``tan(vertical_half_fov_deg)``. The thesis gives the plane's height in pixels (500) but not the
focal length; a half field of view of 20 degrees reproduces its noise-free iteration counts in
all four worlds and in square rooms of 3 to 50 m (tables B.1, B.2), so it is the default.

Disturbances are drawn anew for every projection (section 4.2): Gaussian noise on the
feature positions, ``removed_features`` features hidden at random, ``fake_features`` points
spread uniformly in the room's box, and a rotation of the whole projection drawn uniformly
from ``[0, max_rotation_rad]``.

All runs of one setting advance together as rows of arrays; runs that end are dropped from the
arrays, so a step costs in proportion to the runs still going.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from homing.alv import rotate_vectors_2d

WORLD_WALLS: dict[int, tuple[int, ...]] = {1: (1, 2, 3, 4), 2: (3, 4), 3: (1, 3), 4: (3,)}


class Outcome(IntEnum):
    """How a run ended; the failure criteria of section 4.1."""

    RUNNING = 0
    SUCCESS = 1
    MAX_ITERATIONS = 2
    MAX_EMPTY_PROJECTIONS = 3
    MAX_DISTANCE = 4


@dataclass(frozen=True)
class SimulationParams:
    """One setting of the simulation; defaults are table 4.1's bold values and section 4.1."""

    world: int = 1
    wall_length_x_m: float = 5.0
    wall_length_y_m: float = 5.0
    features: int = 1000
    noise_sd_m: float = 0.0
    fake_features: int = 0
    removed_features: int = 0
    max_rotation_rad: float = 0.0
    start_xy_m: tuple[float, float] = (-1.0, -1.0)
    goal_xy_m: tuple[float, float] = (1.0, 1.0)
    wall_height_m: float = 2.0
    roughness_m: float = 0.001
    camera_height_m: float = 1.0
    min_range_m: float = 0.1
    vertical_half_fov_deg: float = 20.0
    arrival_radius_m: float = 0.1
    max_iterations: int = 2000
    max_empty_projections: int = 5
    max_distance_factor: float = 10.0
    random_vector_max_m: float = 0.5

    def __post_init__(self) -> None:
        if self.world not in WORLD_WALLS:
            raise ValueError(f"world must be one of {sorted(WORLD_WALLS)}, got {self.world}")
        if self.features < 1:
            raise ValueError(f"features must be at least 1, got {self.features}")
        if not 0 <= self.removed_features <= self.features:
            raise ValueError(
                f"removed_features must be in 0..{self.features}, got {self.removed_features}"
            )
        if self.fake_features < 0 or self.noise_sd_m < 0 or self.max_rotation_rad < 0:
            raise ValueError("fake_features, noise_sd_m and max_rotation_rad must be >= 0")
        if min(self.wall_length_x_m, self.wall_length_y_m) <= 0:
            raise ValueError("wall lengths must be positive")

    @property
    def cylinder_half_height(self) -> float:
        """Half the image plane's height on the unit cylinder: ``tan(vertical_half_fov_deg)``."""
        return float(np.tan(np.deg2rad(self.vertical_half_fov_deg)))

    @property
    def ideal_distance_m(self) -> float:
        """Straight-line distance from start to goal."""
        return float(np.hypot(*np.subtract(self.goal_xy_m, self.start_xy_m)))


@dataclass(frozen=True)
class Views:
    """A batch of projections, one row per run.

    ``bearing_rad`` are world-frame azimuths plus the projection's random rotation, ``visible``
    says which columns hold a seen feature, ``alv`` is the 2-D ALV of the visible features
    (NaN where none) and ``rotation_rad`` the rotation applied (unknown to a controller).
    """

    bearing_rad: np.ndarray
    visible: np.ndarray
    alv: np.ndarray
    count: np.ndarray
    rotation_rad: np.ndarray

    def select(self, rows: np.ndarray) -> Views:
        """The views of the runs picked by ``rows`` (a boolean mask or indices)."""
        return Views(
            self.bearing_rad[rows],
            self.visible[rows],
            self.alv[rows],
            self.count[rows],
            self.rotation_rad[rows],
        )


def sample_features(params: SimulationParams, runs: int, rng: np.random.Generator) -> np.ndarray:
    """Feature positions (runs, features, 3) in metres, spread evenly over the present walls."""
    walls = WORLD_WALLS[params.world]
    half_x, half_y = params.wall_length_x_m / 2, params.wall_length_y_m / 2
    per_wall = np.full(len(walls), params.features // len(walls))
    per_wall[: params.features % len(walls)] += 1
    parts = []
    for wall, n in zip(walls, per_wall, strict=True):
        along_x = wall in (1, 3)
        half_along, offset = (half_x, half_y) if along_x else (half_y, half_x)
        sign = -1.0 if wall in (1, 4) else 1.0
        along = rng.uniform(-half_along, half_along, (runs, n))
        across = sign * offset + rng.uniform(-params.roughness_m, params.roughness_m, (runs, n))
        z = rng.uniform(0.0, params.wall_height_m, (runs, n))
        xy = (along, across) if along_x else (across, along)
        parts.append(np.stack([*xy, z], axis=-1))
    return np.concatenate(parts, axis=1)


def project(
    features: np.ndarray,
    position_xy_m: np.ndarray,
    params: SimulationParams,
    rng: np.random.Generator,
    with_bearings: bool = False,
) -> Views:
    """``AcquireCylinder`` for a batch: project features (r, n, 3) seen from positions (r, 2).

    Bearings are computed only when ``with_bearings`` (a compass needs them; the ALV does not:
    a unit vector is ``(dx, dy) / range``).
    """
    runs = len(features)
    points = features
    if params.noise_sd_m > 0:
        points = points + rng.normal(0.0, params.noise_sd_m, points.shape)
    kept = np.ones(points.shape[:2], dtype=bool)
    if params.removed_features > 0:
        scores = rng.random(points.shape[:2])
        kth = np.partition(scores, params.removed_features - 1, axis=1)
        kept = scores > kth[:, params.removed_features - 1 : params.removed_features]
    if params.fake_features > 0:
        half = np.array([params.wall_length_x_m / 2, params.wall_length_y_m / 2])
        fake = rng.uniform(0.0, 1.0, (runs, params.fake_features, 3))
        fake[..., :2] = (2 * fake[..., :2] - 1) * half
        fake[..., 2] *= params.wall_height_m
        points = np.concatenate([points, fake], axis=1)
        kept = np.concatenate([kept, np.ones((runs, params.fake_features), dtype=bool)], axis=1)
    dx = points[..., 0] - position_xy_m[:, :1]
    dy = points[..., 1] - position_xy_m[:, 1:2]
    dz = points[..., 2] - params.camera_height_m
    horizontal = np.hypot(dx, dy)
    visible = kept & (horizontal * horizontal + dz * dz >= params.min_range_m**2)
    visible &= np.abs(dz) <= params.cylinder_half_height * horizontal
    count = visible.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        inverse = np.where(visible, 1.0 / horizontal, 0.0)
        alv = np.stack([(dx * inverse).sum(axis=1), (dy * inverse).sum(axis=1)], axis=1)
        alv /= count[:, None]
    rotation = rng.uniform(0.0, params.max_rotation_rad, runs)
    if params.max_rotation_rad > 0:
        alv = rotate_vectors_2d(alv, rotation)
    bearing = np.arctan2(dy, dx) + rotation[:, None] if with_bearings else np.empty((runs, 0))
    return Views(bearing, visible, alv, count, rotation)


@dataclass
class RunState:
    """What a controller may keep between steps for its runs (rows follow the active runs)."""

    previous_alv: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    def select(self, keep: np.ndarray) -> RunState:
        """The state of the runs picked by the boolean mask ``keep``."""
        return RunState(self.previous_alv[keep], {k: v[keep] for k, v in self.extra.items()})


# A controller turns the goal view and the current view into a move (r, 2) in metres, world
# frame, or NaN rows when the view is empty. It may update ``state`` in place.
Controller = Callable[[Views, Views, RunState, SimulationParams, np.random.Generator], np.ndarray]


def thesis_controller(
    goal: Views, here: Views, state: RunState, params: SimulationParams, rng: np.random.Generator
) -> np.ndarray:
    """Appendix A: move by the home vector ``ALV(here) - ALV(goal)`` itself.

    With an empty view the previous ALV is reused, or (on the first step, or when it had length
    zero) a random ALV of length up to ``random_vector_max_m`` — exactly as the pseudocode does.
    """
    alv = here.alv.copy()
    empty = here.count == 0
    if np.any(empty):
        previous = state.previous_alv[empty]
        usable = np.all(np.isfinite(previous), axis=1) & (np.hypot(*previous.T) > 0)
        angle = rng.uniform(-np.pi, np.pi, int(empty.sum()))
        length = rng.uniform(0.0, params.random_vector_max_m, int(empty.sum()))
        random_alv = np.stack([np.cos(angle), np.sin(angle)], axis=1) * length[:, None]
        alv[empty] = np.where(usable[:, None], previous, random_alv)
    state.previous_alv = alv
    return alv - goal.alv


@dataclass(frozen=True)
class BatchResult:
    """Per-run results of one setting: outcome, iterations, distances, and optional tracks."""

    outcome: np.ndarray
    iterations: np.ndarray
    travelled_m: np.ndarray
    excess_distance_m: np.ndarray
    tracks: list[np.ndarray] | None = None


def simulate_runs(
    params: SimulationParams,
    runs: int,
    rng: np.random.Generator,
    controller: Controller = thesis_controller,
    needs_bearings: bool = False,
    keep_tracks: bool = False,
) -> BatchResult:
    """Run appendix A's ``go`` for ``runs`` independent worlds of one setting.

    ``excess_distance_m`` is the driven path length minus the straight distance from the start
    to where the run stopped (the thesis's "difference with ideal"; see docs/thesis.md for why).
    """
    features = sample_features(params, runs, rng)
    goal_xy = np.tile(np.asarray(params.goal_xy_m, dtype=float), (runs, 1))
    start_xy = np.tile(np.asarray(params.start_xy_m, dtype=float), (runs, 1))
    goal_view = project(features, goal_xy, params, rng, with_bearings=needs_bearings)

    outcome = np.full(runs, Outcome.RUNNING, dtype=np.int8)
    iterations = np.zeros(runs, dtype=np.int64)
    travelled = np.zeros(runs)
    final_xy = start_xy.copy()
    # No feature seen from the goal: the thesis returns before the first step.
    outcome[goal_view.count == 0] = Outcome.MAX_EMPTY_PROJECTIONS

    running = outcome == Outcome.RUNNING
    ids, goal = np.flatnonzero(running), goal_view.select(running)
    feats, pos = features[ids], start_xy[ids]
    trav, iters = np.zeros(len(ids)), np.zeros(len(ids), dtype=np.int64)
    empty = np.zeros(len(ids), dtype=np.int64)
    state = RunState(np.full((len(ids), 2), np.nan))
    tracks: list[list[np.ndarray]] = [[start_xy[i].copy()] for i in range(runs)]
    max_distance = params.max_distance_factor * params.ideal_distance_m
    while len(ids):
        distance = np.hypot(*(pos - goal_xy[ids]).T)
        ended = np.full(len(ids), Outcome.RUNNING, dtype=np.int8)
        ended[trav > max_distance] = Outcome.MAX_DISTANCE
        ended[empty > params.max_empty_projections] = Outcome.MAX_EMPTY_PROJECTIONS
        ended[iters >= params.max_iterations] = Outcome.MAX_ITERATIONS
        ended[distance <= params.arrival_radius_m] = Outcome.SUCCESS
        done = ended != Outcome.RUNNING
        if np.any(done):
            finished = ids[done]
            outcome[finished], iterations[finished] = ended[done], iters[done]
            travelled[finished], final_xy[finished] = trav[done], pos[done]
            keep = ~done
            ids, feats, pos, trav, iters, empty = (
                ids[keep],
                feats[keep],
                pos[keep],
                trav[keep],
                iters[keep],
                empty[keep],
            )
            goal, state = goal.select(keep), state.select(keep)
            if not len(ids):
                break
        here = project(feats, pos, params, rng, with_bearings=needs_bearings)
        empty = np.where(here.count == 0, empty + 1, 0)
        move = controller(goal, here, state, params, rng)
        trav += np.hypot(*move.T)
        pos = pos + move
        iters += 1
        if keep_tracks:
            for row, run in enumerate(ids):
                tracks[run].append(pos[row].copy())
    excess = travelled - np.hypot(*(final_xy - start_xy).T)
    return BatchResult(
        outcome,
        iterations,
        travelled,
        excess,
        [np.array(t) for t in tracks] if keep_tracks else None,
    )
