"""toploc's homing controller for the thesis's simulation (``--method best``).

Appendix A moves by the raw home vector ``ALV(here) - ALV(goal)``. Its length is a gain times
the distance to go, and the gain shrinks with the room (1e-6 m steps in a 50 m room, section
4.3.5); a rotated projection turns it (table B.4). This controller keeps the ALV's direction and
fixes the rest:

1. **Matched features only.** The home vector is the ALV difference over the features seen in
   both views (:func:`matched_home_vectors`, by :func:`homing.alv.matched_home_vector`). The
   simulated features keep their identity from view to view, as descriptor matches do on real
   images; fake features never match, so they never enter, and with features removed both
   ALVs are taken over one set instead of two random subsets. Each matched feature's term is a
   descent direction for the distance to the goal, so even one or two matches point home. A
   view that matches nothing is not acted on: the robot stays and looks again (the next view
   hides other features).
2. **Alignment.** A visual compass estimates the rotation ``delta`` of the current view against
   the goal view (the circular mean of matched bearing differences,
   :func:`homing.compass.matched_shift_rad`), and the current bearings are turned back by it.
   A bearing histogram compass cannot serve here: in the point-symmetric rooms of the
   simulation the view from the start is nearly the goal view turned by 180 degrees (the
   thesis's figure 5.5). With fewer than ``COMPASS_MIN_MATCHES`` matches the last estimate is
   kept. In world 4 (one wall) parallax looks like a rotation: from the start, the goal 0.5 m
   from the wall seems turned by about 90 degrees. So a second hypothesis, "the heading is
   right as it is" (no compass), runs beside the compass one, and the controller follows the
   one whose home vectors better explain its own moves (next point), after
   ``MIN_EVIDENCE_STEPS`` moves.
3. **The goal snapshot's frame, learned from motion.** The goal view was itself taken in an
   unknown orientation, which turns every home vector by the same angle. After a move ``m``
   (known in the robot's drive frame) the home vector changes by about ``-K R m``; the angle
   between ``-change`` and ``m``, accumulated as a weighted circular mean over the moves,
   estimates that rotation, and the home vector is turned back by it. The mean resultant
   length of those angles says how consistent a hypothesis is with the robot's motion.
4. **Adaptive gain.** The move is ``gain * home`` as in appendix A, but the gain grows by
   ``GAIN_UP`` while successive home vectors agree in direction and falls by ``GAIN_DOWN`` when
   they reverse (an overshoot), as Rprop does, never below ``GAIN_MIN`` (the thesis's own gain:
   noisy directions reverse half the time and would otherwise shrink it to nothing); a move is
   at most ``MAX_STEP_M`` long. In a long room, where the thesis's moves shrink to
   micrometres, the gain makes up the difference.

With an empty view the previous move is repeated, as the thesis does.
"""

from __future__ import annotations

import numpy as np

from homing.alv import matched_home_vector, rotate_vectors_2d
from homing.compass import matched_shift_rad
from homing.thesis.simulation import RunState, SimulationParams, Views

PROBE_STEP_M = 0.1
MAX_STEP_M = 1.0
GAIN_UP = 1.5
GAIN_DOWN = 0.5
GAIN_MIN = 1.0
COMPASS_MIN_MATCHES = 5
MIN_EVIDENCE_STEPS = 3
FRAME_SETTLED = 0.7


def matched_home_vectors(
    goal: Views, here: Views, features: int, held_delta_rad: np.ndarray, hold: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Home vectors (r, 2) in each goal view's frame from the features both views see.

    Columns ``0..features-1`` of both views are the world's features; the fake ones after them
    are new in every view and never match, so they never enter. The home vector is
    :func:`homing.alv.matched_home_vector` in the goal view's frame, the ALV difference
    restricted to one feature set, i.e. the mean over matched features of
    ``u_here(b - delta) - u_goal(b)``: each term is a descent direction for the distance to the
    goal (the distance to a point is convex), so a few matches still point home, where the ALV
    of all visible features would compare two different random subsets. ``delta`` is the compass
    (:func:`homing.compass.matched_shift_rad`) where at least ``COMPASS_MIN_MATCHES`` match,
    else ``held_delta_rad`` (the last estimate: one or two matches would absorb the whole signal).

    Returns the home vectors (NaN rows where nothing matches), the compass used (rad) and the
    number of matches.
    """
    n = features
    matched = goal.visible[:, :n] & here.visible[:, :n]
    count = matched.sum(axis=1)
    goal_b, here_b = goal.bearing_rad[:, :n], here.bearing_rad[:, :n]
    estimate = matched_shift_rad(goal_b, here_b, matched)
    delta = np.where((count >= COMPASS_MIN_MATCHES) & (not hold), estimate, held_delta_rad)
    home = matched_home_vector(here_b, goal_b, delta, matched, frame="goal")
    return home, delta, count


def _learn_frames(extra: dict[str, np.ndarray], homes: np.ndarray) -> None:
    """Add the last move's evidence to each hypothesis's goal-frame phasor sum.

    ``homes`` (r, h, 2) are this step's home vectors under each hypothesis; after a move ``m``
    the home vector changes by about ``-K R m``, so the angle from ``m`` to ``-change``
    estimates ``R``. How well the phasors agree (their mean resultant length) also says how
    well a hypothesis explains the robot's own motion.
    """
    change, move = homes - extra["home"], extra["move"][:, None, :]
    usable = np.all(np.isfinite(change), axis=2) & np.all(np.isfinite(move), axis=2)
    usable &= np.hypot(move[..., 0], move[..., 1]) > 0
    c = np.where(usable[..., None], -change, 0.0)
    m = np.where(usable[..., None], move, 0.0)
    angle = np.arctan2(c[..., 1], c[..., 0]) - np.arctan2(m[..., 1], m[..., 0])
    weight = np.hypot(c[..., 0], c[..., 1]) * np.hypot(m[..., 0], m[..., 1])
    extra["frame"] += weight[..., None] * np.stack([np.cos(angle), np.sin(angle)], -1)
    extra["weight"] += weight
    extra["steps"] += usable


def _settledness(extra: dict[str, np.ndarray]) -> np.ndarray:
    """Mean resultant length (r, h) of each hypothesis's frame phasors (0 before any)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.hypot(extra["frame"][..., 0], extra["frame"][..., 1]) / extra["weight"]
    return np.nan_to_num(r)


def best_controller(
    goal: Views, here: Views, state: RunState, params: SimulationParams, rng: np.random.Generator
) -> np.ndarray:
    """One step of toploc's controller for a batch of runs; see the module docstring."""
    runs = len(here.count)
    seen = here.count > 0
    extra = state.extra
    if "frame" not in extra:
        extra.update(
            frame=np.zeros((runs, 2, 2)),  # per hypothesis: sum of goal-frame phasors
            weight=np.zeros((runs, 2)),
            steps=np.zeros((runs, 2)),
            gain=np.ones(runs),
            delta=np.zeros(runs),
            home=np.full((runs, 2, 2), np.nan),
            move=np.full((runs, 2), np.nan),
        )
    # Hypothesis 0: the compass turns the view; hypothesis 1: the heading is trusted as is.
    compassed, extra["delta"], matches = matched_home_vectors(
        goal, here, params.features, extra["delta"]
    )
    trusted, _, _ = matched_home_vectors(goal, here, params.features, np.zeros(runs), True)
    homes = np.stack([compassed, trusted], axis=1)
    homes[~seen] = np.nan
    _learn_frames(extra, homes)
    settled = _settledness(extra)
    pick = (settled[:, 1] > settled[:, 0]) & (extra["steps"][:, 1] >= MIN_EVIDENCE_STEPS)
    rows = np.arange(runs)
    home = homes[rows, pick.astype(int)]
    previous = extra["home"][rows, pick.astype(int)]
    agree = np.nan_to_num((home * previous).sum(axis=1)) > 0
    update = np.all(np.isfinite(home), axis=1) & np.all(np.isfinite(previous), axis=1)
    gain = extra["gain"] * np.where(agree, GAIN_UP, GAIN_DOWN)
    extra["gain"] = np.where(update, np.maximum(gain, GAIN_MIN), extra["gain"])

    # Turn only by a settled estimate of the goal view's frame.
    frame = extra["frame"][rows, pick.astype(int)]
    frame_rad = np.where(
        settled[rows, pick.astype(int)] > FRAME_SETTLED, np.arctan2(frame[:, 1], frame[:, 0]), 0.0
    )
    move = rotate_vectors_2d(home, -frame_rad) * extra["gain"][:, None]
    length = np.hypot(*move.T)
    with np.errstate(invalid="ignore", divide="ignore"):
        move *= np.where(length > MAX_STEP_M, MAX_STEP_M / length, 1.0)[:, None]

    # Features seen but none matched: stay and look again (the next view hides others).
    move[seen & (matches == 0)] = 0.0
    # Empty view: repeat the previous move, or probe at random on the first step (appendix A).
    previous_move = extra["move"]
    stuck = ~np.all(np.isfinite(move), axis=1)
    if np.any(stuck):
        angle = rng.uniform(-np.pi, np.pi, int(stuck.sum()))
        probe = PROBE_STEP_M * np.stack([np.cos(angle), np.sin(angle)], 1)
        before = previous_move[stuck]
        move[stuck] = np.where(np.all(np.isfinite(before), axis=1)[:, None], before, probe)
    extra["home"] = np.where(np.isfinite(homes), homes, extra["home"])
    extra["move"] = move
    return move
