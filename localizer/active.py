"""Active disambiguation (thesis chapter 6): while the belief is ambiguous, drive to a telling
place by visual homing, look again there, and update the belief.

Works with any :class:`localizer.robot_protocol.Robot`; the policy that picks where to go is
pluggable (:mod:`localizer.policy`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from localizer.belief import LocalizationState, RoomBelief
from localizer.localizer import Localizer, Observation
from localizer.policy import (
    POLICIES,
    DiscriminativePolicy,
    PlaceSimilarity,
    PolicyContext,
    make_policy,
    separating_pairs,
)
from localizer.robot_protocol import Robot
from localizer.visual_homing import HomingParams, HomingResult, drive_home

# A short homing move rarely leaves the room: keep most of the mass where it is.
HOMING_STAY_PROBABILITY = 0.98


@dataclass(frozen=True)
class ActiveParams:
    """``max_targets``: places the robot may drive to before it gives up;
    ``rival_min_probability``: rooms at least this likely are hypotheses the separating policy
    must tell apart; ``homing``: the visual homing loop's settings."""

    max_targets: int = 4
    rival_min_probability: float = 0.02
    homing: HomingParams = field(default_factory=HomingParams)


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
    frames used (captures that went into the belief or into homing) and the distance driven
    (odometric, metres)."""

    first: RoomBelief
    final: RoomBelief
    visits: tuple[Visit, ...]
    frames: int
    distance_m: float


def _similarity_for(
    localizer: Localizer, belief: RoomBelief, min_probability: float, tried: set[int]
) -> PlaceSimilarity:
    """The stored-view similarity the separating policy will read for this belief."""
    candidates, rivals = separating_pairs(belief, localizer.map.places, tried, min_probability)
    return localizer.similarity(candidates, rivals)


def localize_actively(
    localizer: Localizer,
    robot: Robot,
    policy: str = "separating",
    params: ActiveParams | None = None,
    on_belief: Callable[[RoomBelief], None] | None = None,
) -> ActiveResult:
    """Localize from a uniform belief, driving to disambiguate while the belief is ambiguous.

    ``policy`` names a policy of :data:`localizer.policy.POLICIES`; the ``separating`` one
    gets the stored-view similarity of the places of the rooms still in play. ``on_belief`` is
    called with each new belief (state ``homing`` while driving).
    """
    if policy not in POLICIES:
        raise ValueError(f"unknown policy {policy!r}; known: {', '.join(sorted(POLICIES))}")
    params = params or ActiveParams()
    notify = on_belief or (lambda belief: None)
    localizer.reset()
    observation = localizer.observe(robot.capture().image)
    belief = localizer.update(observation)
    first, frames, distance = belief, 1, 0.0
    notify(belief)
    visits: list[Visit] = []
    tried: set[int] = set()
    while belief.state is LocalizationState.AMBIGUOUS and len(visits) < params.max_targets:
        target = _choose(localizer, policy, belief, observation, tried, params)
        if target is None:
            break
        tried.add(target)
        notify(localizer.belief(LocalizationState.HOMING))
        goal = localizer.map.fingerprint(target)
        homing = drive_home(robot, goal, localizer.extract, params.homing)
        frames += len(homing.lengths) + 1
        distance += homing.distance_m
        localizer.predict(HOMING_STAY_PROBABILITY)
        observation = localizer.observe(robot.capture().image)
        belief = localizer.update(observation)
        notify(belief)
        visits.append(Visit(target, localizer.map.place(target).room, homing, belief))
    return ActiveResult(first, belief, tuple(visits), frames, distance)


def _choose(
    localizer: Localizer,
    policy: str,
    belief: RoomBelief,
    observation: Observation,
    tried: set[int],
    params: ActiveParams,
) -> int | None:
    options = {}
    if policy == DiscriminativePolicy.name:
        options["similarity"] = _similarity_for(
            localizer, belief, params.rival_min_probability, tried
        )
        options["min_rival_probability"] = params.rival_min_probability
    return make_policy(policy, **options).choose(
        belief, observation.evidence.places, localizer.map.places, tried, PolicyContext()
    )
