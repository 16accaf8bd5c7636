"""Active disambiguation (thesis chapter 6): while the belief is ambiguous, drive to a telling
place by visual homing, look again there, and update the belief.

Works with any :class:`localizer.robot_protocol.Robot`; the policy that picks where to go is
pluggable (:mod:`localizer.policy`), and so is how the robot gets to a place (``home``: by
default :func:`~localizer.visual_homing.drive_home`; the service passes its homing node's, so
that a drive publishes progress and can be cancelled).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

from localizer.belief import LocalizationState, RoomBelief
from localizer.likelihood import PlaceScore
from localizer.localizer import Localizer
from localizer.policy import Policy, PolicyContext, make_policy
from localizer.robot_protocol import Robot
from localizer.visual_homing import HomingParams, HomingResult, drive_home
from mapdb.records import Place

# A short homing move rarely leaves the room: keep most of the mass where it is.
HOMING_STAY_PROBABILITY = 0.98
CANCELLED = "cancelled"
"""The :attr:`HomingResult.reason` of a drive someone cancelled: no further drive follows."""

ENDINGS: dict[str, str] = {
    "settled": "the belief is no longer ambiguous",
    "lost": "the robot, lost, looked elsewhere and still matched no room",
    "no-telling-place": "the policy has no place left that tells the likely rooms apart",
    "drive-limit": "the robot made the drives it may make (ActiveParams.max_targets)",
    CANCELLED: "a drive was cancelled",
}
"""Why an active localization ended (:attr:`ActiveResult.ended`), with what each means."""


@dataclass(frozen=True)
class ActiveParams:
    """``max_targets``: places the robot may drive to before it gives up; ``homing``: the
    visual homing loop's settings. ``lost_looks``: while the belief is ``lost``, the robot
    turns by ``lost_turn_deg``, drives ``lost_step_m`` and looks again, at most this many
    times (a robot woken facing a bare wall or a doorway sees little; a step away it may see
    its room; 12 of 48 kidnappings on recorded maps ended ``lost`` without a move, issue 19).
    ``min_new_view_m``: a drive shorter than this (odometric) ends where the robot already
    looked, and its frame is not folded into the belief again: the same view twice is one
    piece of evidence, not two (homing to a counterpart at the spot the robot stands on
    drives nowhere, and its frame repeated the last one's counts to the inlier)."""

    max_targets: int = 4
    homing: HomingParams = field(default_factory=HomingParams)
    lost_looks: int = 2
    lost_turn_deg: float = 120.0
    lost_step_m: float = 0.5
    min_new_view_m: float = 0.1

    def __post_init__(self) -> None:
        if self.max_targets < 0 or self.lost_looks < 0:
            raise ValueError(
                f"max_targets and lost_looks must be >= 0, got {self.max_targets}, "
                f"{self.lost_looks}"
            )
        if not (math.isfinite(self.lost_turn_deg) and math.isfinite(self.lost_step_m)):
            raise ValueError("lost_turn_deg and lost_step_m must be finite")
        if not self.min_new_view_m >= 0.0:
            raise ValueError(f"min_new_view_m must be >= 0, got {self.min_new_view_m!r}")


@dataclass(frozen=True)
class Visit:
    """One drive to a target place and the belief after looking there."""

    place_id: int
    room: str
    homing: HomingResult
    belief: RoomBelief


@dataclass(frozen=True)
class ActiveResult:
    """How an active localization went: the first and final beliefs, every visit, the
    frames used (captures that went into the belief or into homing), the distance driven
    (odometric, metres), how many times the robot, lost, stepped away to look again, and why
    it ended (a key of :data:`ENDINGS`: an ambiguous belief with ``"no-telling-place"`` is
    look-alike rooms that the map has no place to tell apart)."""

    first: RoomBelief
    final: RoomBelief
    visits: tuple[Visit, ...]
    frames: int
    distance_m: float
    looks_elsewhere: int = 0
    ended: str = "settled"


def active_step(
    belief: RoomBelief,
    evidence: Sequence[PlaceScore],
    places: Sequence[Place],
    policy: Policy,
    context: PolicyContext,
    max_targets: int,
    drives: int,
) -> int | None:
    """The place to drive to next, or ``None`` when active localization is done: the belief is
    not ambiguous, ``drives`` drives were made of the ``max_targets`` allowed, or the policy has
    nothing left."""
    if belief.state is not LocalizationState.AMBIGUOUS or drives >= max_targets:
        return None
    return policy.choose(belief, evidence, places, context)


def localize_actively(
    localizer: Localizer,
    robot: Robot,
    policy: Policy | str = "separating",
    params: ActiveParams | None = None,
    on_belief: Callable[[RoomBelief], None] | None = None,
    home: Callable[[int], HomingResult] | None = None,
) -> ActiveResult:
    """Localize from a uniform belief, driving to disambiguate while the belief is ambiguous.

    ``policy``: a :class:`~localizer.policy.Policy` or the name of one in
    :data:`localizer.policy.POLICIES`; its context offers the localizer's stored-view
    similarity, computed only where the policy asks. ``on_belief`` is called with each new
    belief (state ``homing`` while driving). ``home(place_id)`` drives the robot to a place
    (default: :func:`drive_home` toward its stored fingerprint with ``params.homing``); a drive
    that ends with reason :data:`CANCELLED` is the last: the robot looks once where it stopped.
    While the belief is ``lost`` the robot steps away and looks again (``params.lost_looks``).
    A drive shorter than ``params.min_new_view_m`` adds no frame to the belief, and a drive
    to a place also ends the drives to its counterparts at the same spot
    (:meth:`Localizer.same_spot_places`): from there the robot has looked already.
    """
    chosen = make_policy(policy) if isinstance(policy, str) else policy
    params = params or ActiveParams()
    notify = on_belief or (lambda belief: None)

    def drive_to(place_id: int) -> HomingResult:
        goal = localizer.map.fingerprint(place_id)
        return drive_home(robot, goal, localizer.extract, params.homing)

    go = home or drive_to
    localizer.reset()
    observation = localizer.observe(robot.capture().image)
    belief = localizer.update(observation)
    first, frames, distance = belief, 1, 0.0
    notify(belief)
    visits: list[Visit] = []
    context = PolicyContext(
        similarity=localizer.similarity,
        lookalikes=localizer.lookalikes,
        counterparts=localizer.counterparts,
    )
    looks_elsewhere = 0
    while True:
        if belief.state is LocalizationState.LOST and looks_elsewhere < params.lost_looks:
            looks_elsewhere += 1
            moved = robot.move(math.radians(params.lost_turn_deg), params.lost_step_m)
            distance += abs(moved.moved_m)
            localizer.predict(HOMING_STAY_PROBABILITY)
            observation = localizer.observe(robot.capture().image)
            belief = localizer.update(observation)
            frames += 1
            notify(belief)
            continue
        target = active_step(
            belief,
            observation.evidence.places,
            localizer.map.places,
            chosen,
            context,
            params.max_targets,
            len(visits),
        )
        if target is None:
            ended = _ending(belief, len(visits), params.max_targets)
            break
        context = context.trying(target)
        for same_spot in localizer.same_spot_places(target):  # looked at from there already
            context = context.trying(same_spot)
        notify(localizer.belief(LocalizationState.HOMING))
        homing = go(target)
        frames += len(homing.lengths)
        distance += homing.distance_m
        if homing.distance_m >= params.min_new_view_m:
            localizer.predict(HOMING_STAY_PROBABILITY)
            observation = replace(localizer.observe(robot.capture().image), at_place=target)
            belief = localizer.update(observation)
            frames += 1
        else:
            belief = localizer.belief()
        notify(belief)
        visits.append(Visit(target, localizer.map.place(target).room, homing, belief))
        if homing.reason == CANCELLED:
            ended = CANCELLED
            break
    return ActiveResult(first, belief, tuple(visits), frames, distance, looks_elsewhere, ended)


def _ending(belief: RoomBelief, drives: int, max_targets: int) -> str:
    """Why the loop stopped asking for a drive (see :func:`active_step`): a key of
    :data:`ENDINGS`."""
    if belief.state is LocalizationState.LOST:
        return "lost"
    if belief.state is not LocalizationState.AMBIGUOUS:
        return "settled"
    return "drive-limit" if drives >= max_targets else "no-telling-place"
