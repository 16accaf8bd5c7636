"""Where a robot that cannot tell where it is looks next, for the active loop
(:func:`localizer.active.localize_actively`): the place a look matched too faintly to tell a
room, homed to first (:func:`faintly_seen`); out of a corner, a step towards the features a
look verified, which lie across the room (:func:`matched_bearing_rad`,
:func:`step_away_if_stuck`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from localizer.likelihood import PlaceScore
from localizer.localizer import Observation
from localizer.robot_protocol import Pose2D, Robot


def matched_bearing_rad(observation: Observation, min_features: int = 5) -> float | None:
    """The robot-frame bearing (radians, CCW from the heading) of the mean direction of the
    query's features that ``observation`` verified with any place; None when fewer than
    ``min_features`` were verified, or when they surround the robot so evenly that their mean
    direction is shorter than 0.1.

    A robot woken in a corner, facing walls it matches nothing on, matches what lies across
    the room: the two robots that ended ``lost`` 0.4-0.6 m from a bedroom's back wall on world
    seed 47's recorded house matched 21 and 41 features, and their mean bearing pointed within
    6° and 1° of the room's middle."""
    verified = [
        item.inlier_pairs[:, 0] for item in observation.evidence.places if len(item.inlier_pairs)
    ]
    if not verified:
        return None
    bearings_rad = observation.fingerprint.bearings_rad[np.unique(np.concatenate(verified))]
    if len(bearings_rad) < min_features:
        return None
    mean = np.array([np.cos(bearings_rad).mean(), np.sin(bearings_rad).mean()])
    if np.hypot(*mean) < 0.1:
        return None
    return float(np.arctan2(mean[1], mean[0]))


def step_away_if_stuck(
    robot: Robot,
    observation: Observation,
    began: Pose2D,
    stuck_m: float,
    step_m: float,
    turn_deg: float,
) -> float | None:
    """If the robot stands less than ``stuck_m`` from ``began`` (odometry, where the
    drive that gave up began), step ``step_m`` towards the features
    ``observation`` verified (:func:`matched_bearing_rad`, turned back by the turns made since
    it was taken: its odometry, else ``began``), or after a turn of ``turn_deg``
    when too few were verified to say where. Returns the distance driven (metres), or None
    when the robot was not stuck."""
    now = robot.odometry()
    if math.dist((now.x_m, now.y_m), (began.x_m, began.y_m)) >= stuck_m:
        return None
    seen_rad = matched_bearing_rad(observation)
    if seen_rad is None:
        turn_rad = math.radians(turn_deg)
    else:  # the bearing was taken before the turns since (a look kept from an earlier arrival)
        seen_from = began if observation.odometry is None else observation.odometry
        turn_rad = seen_rad - (now.heading_rad - seen_from.heading_rad)
    return step_away(robot, math.remainder(turn_rad, math.tau), step_m)


def step_away(robot: Robot, turn_rad: float, step_m: float) -> float:
    """Turn by ``turn_rad`` and drive ``step_m``; a step that bumps before half of it is
    driven the other way (turned round). Returns the distance driven (metres)."""
    moved = robot.move(turn_rad, step_m)
    driven = abs(moved.moved_m)
    if moved.bumped and driven < step_m / 2:
        driven += abs(robot.move(math.pi, step_m).moved_m)
    return driven


def faintly_seen(observation: Observation, min_inliers: int, tried: set[int]) -> int | None:
    """The place ``observation`` matched best (most spread inliers) among those with at least
    ``min_inliers`` verified inliers and not in ``tried``; None if there is none."""
    return best_matched(
        [
            item
            for item in observation.evidence.places
            if item.inliers >= min_inliers and item.place_id not in tried
        ]
    )


def best_matched(items: Sequence[PlaceScore]) -> int | None:
    """The id of the place of ``items`` with most spread inliers (ties: the lower id); None
    for no items."""
    if not items:
        return None
    return max(items, key=lambda item: (item.spread_inliers, -item.place_id)).place_id
