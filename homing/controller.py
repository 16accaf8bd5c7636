"""toploc's homing controller for the thesis's simulation (``--method best``).

Appendix A moves by the raw home vector ``ALV(here) - ALV(goal)``. Its length is a gain times
the distance to go, and the gain shrinks with the room (1e-6 m steps in a 50 m room, section
4.3.5); a rotated projection turns it (table B.4). This controller keeps the ALV's direction and
fixes the rest:

1. **Alignment.** A visual compass estimates the rotation ``delta`` of the current view against
   the goal view, and the current ALV is rotated back by it: the home vector is then expressed
   in the goal view's frame. The simulated features keep their identity from view to view (as
   descriptor matches do on real images), so the compass is the circular mean of matched
   bearing differences (:func:`homing.compass.matched_shift_rad`). A bearing histogram compass
   cannot serve here: in the point-symmetric rooms of the simulation the view from the start is
   nearly the goal view turned by 180 degrees (the thesis's figure 5.5).
2. **The goal snapshot's frame, learned from motion.** The goal view was itself taken in an
   unknown orientation, which turns every home vector by the same angle. After a move ``m``
   (known in the robot's drive frame) the home vector changes by about ``-K R m``; the angle
   between ``-change`` and ``m``, accumulated as a weighted circular mean over the moves,
   estimates that rotation, and the home vector is turned back by it.
3. **Adaptive gain.** The move is ``gain * home`` as in appendix A, but the gain grows by
   ``GAIN_UP`` while successive home vectors agree in direction and falls by ``GAIN_DOWN`` when
   they reverse (an overshoot), as Rprop does; a move is at most ``MAX_STEP_M`` long. In a long
   room, where the thesis's moves shrink to micrometres, the gain makes up the difference.

With an empty view the previous move is repeated, as the thesis does.
"""

from __future__ import annotations

import numpy as np

from homing.compass import matched_shift_rad
from homing.simulation import RunState, SimulationParams, Views

PROBE_STEP_M = 0.1
MAX_STEP_M = 1.0
GAIN_UP = 1.5
GAIN_DOWN = 0.5
FRAME_SETTLED = 0.7


def _rotate(vectors: np.ndarray, angle_rad: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.stack(
        [c * vectors[:, 0] - s * vectors[:, 1], s * vectors[:, 0] + c * vectors[:, 1]], 1
    )


def aligned_home_vectors(goal: Views, here: Views, features: int) -> np.ndarray:
    """Home vectors (r, 2) in each goal view's frame: current ALVs de-rotated by the compass.

    Columns ``0..features-1`` of both views are the world's features; the fake ones after them
    are new in every view and never match.
    """
    n = features
    matched = goal.visible[:, :n] & here.visible[:, :n]
    delta = matched_shift_rad(goal.bearing_rad[:, :n], here.bearing_rad[:, :n], matched)
    return _rotate(here.alv, -np.nan_to_num(delta)) - goal.alv


def best_controller(
    goal: Views, here: Views, state: RunState, params: SimulationParams, rng: np.random.Generator
) -> np.ndarray:
    """One step of toploc's controller for a batch of runs; see the module docstring."""
    runs = len(here.count)
    seen = here.count > 0
    extra = state.extra
    if "frame" not in extra:
        extra.update(
            frame=np.zeros((runs, 2)),  # weighted sum of unit phasors of the goal frame's angle
            gain=np.ones(runs),
            weight=np.zeros(runs),
            home=np.full((runs, 2), np.nan),
            move=np.full((runs, 2), np.nan),
        )
    home = np.full((runs, 2), np.nan)
    if np.any(seen):
        home[seen] = aligned_home_vectors(goal.select(seen), here.select(seen), params.features)

    change, previous_move = home - extra["home"], extra["move"]
    usable = np.all(np.isfinite(change), axis=1) & np.all(np.isfinite(previous_move), axis=1)
    if np.any(usable):
        c, m = -change[usable], previous_move[usable]
        angle = np.arctan2(c[:, 1], c[:, 0]) - np.arctan2(m[:, 1], m[:, 0])
        weight = np.hypot(*c.T) * np.hypot(*m.T)
        extra["frame"][usable] += weight[:, None] * np.stack([np.cos(angle), np.sin(angle)], 1)
        extra["weight"][usable] += weight
        agree = (home[usable] * extra["home"][usable]).sum(axis=1) > 0
        extra["gain"][usable] *= np.where(agree, GAIN_UP, GAIN_DOWN)

    # Turn only by a settled estimate: the phasors' mean resultant length says how settled.
    with np.errstate(invalid="ignore", divide="ignore"):
        settled = np.hypot(*extra["frame"].T) > FRAME_SETTLED * extra["weight"]
    frame_rad = np.where(settled, np.arctan2(extra["frame"][:, 1], extra["frame"][:, 0]), 0.0)
    move = _rotate(home, -frame_rad) * extra["gain"][:, None]
    length = np.hypot(*move.T)
    with np.errstate(invalid="ignore", divide="ignore"):
        move *= np.where(length > MAX_STEP_M, MAX_STEP_M / length, 1.0)[:, None]

    # Empty view: repeat the previous move, or probe at random on the first step (appendix A).
    stuck = ~np.all(np.isfinite(move), axis=1)
    if np.any(stuck):
        angle = rng.uniform(-np.pi, np.pi, int(stuck.sum()))
        probe = PROBE_STEP_M * np.stack([np.cos(angle), np.sin(angle)], 1)
        before = previous_move[stuck]
        move[stuck] = np.where(np.all(np.isfinite(before), axis=1)[:, None], before, probe)
    extra["home"] = np.where(seen[:, None], home, extra["home"])
    extra["move"] = move
    return move
