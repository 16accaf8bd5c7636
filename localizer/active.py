"""Active disambiguation (thesis chapter 6): while the belief is ambiguous, drive to a telling
place by visual homing, look again there, and update the belief.

Works with any :class:`localizer.robot_protocol.Robot`; the policy that picks where to go is
pluggable (:mod:`localizer.policy`), and so is how the robot gets to a place (``home``: by
default :func:`~localizer.visual_homing.drive_home`; the service passes its homing node's, so
that a drive publishes progress and can be cancelled).

When the policy has no place left that tells the likely rooms apart (look-alike rooms that
look alike from every place of theirs), the robot checks a likely room by a recorded route
(:mod:`localizer.route_choice` picks it, :mod:`localizer.route_checks` drives it).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

from localizer.belief import LocalizationState, RoomBelief
from localizer.last_looks import closer_look, place_to_end_at, way_in_step
from localizer.likelihood import PlaceScore
from localizer.localizer import Localizer, Observation
from localizer.looking_elsewhere import faintly_seen, step_away_if_stuck
from localizer.policy import Policy, PolicyContext, make_policy
from localizer.robot_protocol import Pose2D, Robot
from localizer.route_checks import RouteCheck, RouteCheckParams, check_route
from localizer.route_choice import (
    likely_twin,
    repeating_ends,
    route_to_check,
    starts_to_check_again,
    telling_checks,
    told_outcomes,
)
from localizer.routes import Route, drive_route, route_through
from localizer.visual_homing import (
    CANCELLED,
    HomingParams,
    HomingResult,
    drive_home,
)
from mapdb.records import Place

# A short homing move rarely leaves the room: keep most of the mass where it is.
HOMING_STAY_PROBABILITY = 0.98

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
    """``max_targets``: drives that tell something the robot may make before it gives up
    (drives that told nothing count once there were as many: :func:`_drives_spent`);
    ``homing``: the visual homing loop's settings. ``lost_looks``: while the belief is
    ``lost``, the robot steps ``lost_step_m`` away and looks again, at most this many times
    (a robot woken facing a bare wall or a doorway sees little; a step away it may see its
    room; 12 of 48 kidnappings on recorded maps ended ``lost`` without a move, issue 19).
    A look that matched a place with at least ``lost_home_min_inliers`` verified inliers, too
    few to tell a room, homes to that place first (each such place once): a robot woken far
    from its room's few stored places sees them faintly, and near one it sees its room (on
    world seed 24's house, two places per room, 4 of 5 kidnappings into one bedroom ended
    ``lost`` after two steps away, and none when homing there). Where that homing ends less
    than ``lost_stuck_m`` from where it began (odometry), or no place was matched, the robot
    steps towards the features the look verified with any place
    (:func:`~localizer.looking_elsewhere.matched_bearing_rad`: in a room's corner they lie
    across the room), or turns by ``lost_turn_deg`` first when too few were verified to say
    where; a step that bumps at once is driven the other way. A route check whose homing to
    its start place gives up that close to where it began, the robot at no place, is followed
    by the same step (:func:`~localizer.looking_elsewhere.step_away_if_stuck`).
    ``min_new_view_m``: a drive shorter than this (odometric) ends where the robot already
    looked, and its frame is not folded into the belief again: the same view twice is one
    piece of evidence, not two (homing to a counterpart at the spot the robot stands on
    drives nowhere, and its frame repeated the last one's counts to the inlier).
    ``end_at_place``: a belief ``localized`` on a frame not taken where the robot homed to a
    place of its room is not the end: the robot homes to that room's place the frame matched
    best and looks there (:func:`~localizer.last_looks.place_to_end_at`), so the loop ends at
    a stored place of the room it names. A robot set down in a doorway sees both rooms, and a
    place recorded near the door may make the next room's the better view: on the recorded
    maps of world seeds 35-57 (960 single looks kidnapped into every room), 11 of the 379
    ``localized`` looks were wrong, 10 of them by robots whose centre stood 0.15-0.42 m from a
    door's centre, on the side of the room they did not name; run whole, 6 ended sure and
    wrong, none with this homing, which takes the robot through that door into the room it
    names.
    ``step_in_m``: a belief ``localized`` on a frame taken at a place of its room recorded on
    a drive in from another room (the first place after a door, where a user records as soon
    as the robot is through it) is looked at once more from the point ``step_in_m`` past the
    place along the way the drive came in, driven to from where homing left the robot
    (:func:`~localizer.last_looks.way_in_step`): homing arrives within about 0.3 m of a place,
    and by a door that may be the far side of it (world seed 59's house recorded one place per
    room: a robot homed to bedroom_a's place, recorded about 0.2 m inside by the door, said
    bedroom_a at 0.962 standing 1 cm into the hall). 0 turns it off.
    ``routes``: how a room is checked by a recorded route (:class:`RouteCheckParams`)."""

    max_targets: int = 4
    homing: HomingParams = field(default_factory=HomingParams)
    lost_looks: int = 3
    lost_turn_deg: float = 120.0
    lost_step_m: float = 0.5
    lost_home_min_inliers: int = 4
    lost_stuck_m: float = 0.3
    min_new_view_m: float = 0.1
    end_at_place: bool = True
    step_in_m: float = 0.5
    routes: RouteCheckParams = field(default_factory=RouteCheckParams)

    def __post_init__(self) -> None:
        if self.max_targets < 0 or self.lost_looks < 0 or self.lost_home_min_inliers < 1:
            raise ValueError(
                "max_targets and lost_looks must be >= 0 and lost_home_min_inliers >= 1, got "
                f"{self.max_targets}, {self.lost_looks}, {self.lost_home_min_inliers}"
            )
        if not (math.isfinite(self.lost_turn_deg) and math.isfinite(self.lost_step_m)):
            raise ValueError("lost_turn_deg and lost_step_m must be finite")
        if not self.lost_stuck_m >= 0.0:
            raise ValueError(f"lost_stuck_m must be >= 0, got {self.lost_stuck_m!r}")
        if not self.min_new_view_m >= 0.0:
            raise ValueError(f"min_new_view_m must be >= 0, got {self.min_new_view_m!r}")
        if not 0.0 <= self.step_in_m < math.inf:
            raise ValueError(f"step_in_m must be finite and >= 0, got {self.step_in_m!r}")


@dataclass(frozen=True)
class Visit:
    """One drive to a target place and the belief after looking there; ``told``: whether the
    drive told anything (False: a route check that could not start, or a drive to a place that
    did not arrive and came back to where the robot had looked from; see
    :func:`_drives_spent`)."""

    place_id: int
    room: str
    homing: HomingResult
    belief: RoomBelief
    told: bool = True


@dataclass(frozen=True)
class ActiveResult:
    """How an active localization went: the first and final beliefs, every visit, the
    frames used (captures that went into the belief or into homing), the distance driven
    (odometric, metres), how many times the robot, lost, stepped away to look again, why
    it ended (a key of :data:`ENDINGS`: an ambiguous belief with ``"no-telling-place"`` is
    look-alike rooms that the map has no place nor route to tell apart) and the rooms checked
    by a recorded route (each also a visit, to the route's end place)."""

    first: RoomBelief
    final: RoomBelief
    visits: tuple[Visit, ...]
    frames: int
    distance_m: float
    looks_elsewhere: int = 0
    ended: str = "settled"
    checks: tuple[RouteCheck, ...] = ()


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
    (:meth:`Localizer.same_spot_places`): from there the robot has looked already. A route
    check that could not start (its homing to the start place did not arrive) is tried once
    more when no other check is left and the belief is still ambiguous.
    """
    chosen = make_policy(policy) if isinstance(policy, str) else policy
    params = params or ActiveParams()

    def drive_to(place_id: int) -> HomingResult:
        goal = localizer.map.fingerprint(place_id)
        return drive_home(robot, goal, localizer.extract, params.homing)

    run = _ActiveRun(localizer, robot, params, home or drive_to, on_belief or (lambda _: None))
    ended = None
    while ended is None:
        ended = run.turn(chosen)
    return ActiveResult(
        run.first,
        run.belief,
        tuple(run.visits),
        run.frames,
        run.distance_m,
        run.looks_elsewhere,
        ended,
        tuple(run.checks),
    )


class _ActiveRun:
    """One active localization under way: what the robot has seen, driven and checked so far,
    and one method per kind of move the loop makes (:meth:`turn` picks the next)."""

    def __init__(
        self,
        localizer: Localizer,
        robot: Robot,
        params: ActiveParams,
        go: Callable[[int], HomingResult],
        notify: Callable[[RoomBelief], None],
    ) -> None:
        self.localizer, self.robot, self.params = localizer, robot, params
        self.go, self.notify = go, notify
        localizer.reset()
        self.observation = _look(localizer, robot)
        self.belief = localizer.update(self.observation)
        self.first = self.belief
        self.frames, self.distance_m, self.looks_elsewhere = 1, 0.0, 0
        notify(self.belief)
        self.visits: list[Visit] = []
        self.checks: list[RouteCheck] = []
        self.context = PolicyContext(
            similarity=localizer.similarity,
            lookalikes=localizer.lookalikes,
            counterparts=localizer.counterparts,
        )
        self.homed_lost: set[int] = set()  # places homed to while lost (each once)
        self.tried_routes: set[int] = set()  # start places of route checks
        self.retried_routes: set[int] = set()  # starts of checks that could not start, retried
        self.looked_closer: set[int] = set()  # places homed to for a last look
        self.stepped_in: set[int] = set()  # places stepped in from

    def turn(self, policy: Policy) -> str | None:
        """One move of the loop (a look elsewhere while lost, a route check, a last look, a
        step in or a drive to the policy's place) and the look after it; why the loop ends (a
        key of :data:`ENDINGS`), or None to go on."""
        params = self.params
        if self.belief.state is LocalizationState.LOST and self.looks_elsewhere < params.lost_looks:
            return self.look_elsewhere()
        spent = _drives_spent(self.visits, params.max_targets)
        target = active_step(
            self.belief,
            self.observation.evidence.places,
            self.localizer.map.places,
            policy,
            self.context,
            params.max_targets,
            spent,
        )
        # rooms where routes of two look-alikes both arrived: a route that ends there tells
        # nothing (repeating_ends)
        repeating = repeating_ends(self.checks, self.localizer.lookalikes, self._room_of)
        check = self.route_check(target, spent, repeating)
        if check is not None:
            return self.drive_check(*check, repeating)
        if target is None:
            target = self.last_look(spent)
        if target is None and self.step_in():
            return None
        if target is None:
            return _ending(self.belief, spent, params.max_targets)
        return self.drive_to(target)

    def _room_of(self, place_id: int) -> str:
        return self.localizer.map.place(place_id).room

    def _look_here(self, at_place: int | None = None) -> None:
        """Look where the robot stands (at place ``at_place``, if it homed to one) after a
        move, and fold the frame into the belief."""
        self.localizer.predict(HOMING_STAY_PROBABILITY)
        self.observation = _look(self.localizer, self.robot, at_place)
        self.belief = self.localizer.update(self.observation)
        self.frames += 1

    def _home(self, place_id: int) -> HomingResult:
        """Drive to place ``place_id`` by ``go``, counting its frames and metres."""
        homing = self.go(place_id)
        self.frames += len(homing.lengths)
        self.distance_m += homing.distance_m
        return homing

    def look_elsewhere(self) -> str | None:
        """Lost: home to the place the last look matched best though too faintly to tell, if
        any (each once), and step out of a corner, then look again (:class:`ActiveParams`)."""
        self.looks_elsewhere += 1
        faint = faintly_seen(self.observation, self.params.lost_home_min_inliers, self.homed_lost)
        began, at_place = self.robot.odometry(), None
        if faint is not None:  # the place it matched best, though too weakly to tell
            self.homed_lost.add(faint)
            if self._home(faint).reason == CANCELLED:
                return CANCELLED
            at_place = faint
        stepped_m = _step_out(self.robot, self.observation, began, self.params)
        if stepped_m is not None:
            self.distance_m += stepped_m
            at_place = None
        self._look_here(at_place)
        self.notify(self.belief)
        return None

    def route_check(
        self, target: int | None, spent: int, repeating: frozenset[str]
    ) -> tuple[Place, Route] | None:
        """The start place of the room to check by a recorded route now, and the route
        (:mod:`localizer.route_choice`): when the top two rooms look alike or the policy has no
        place (``target`` None) and a drive is left, or the top room is to be confirmed
        (:func:`_to_confirm`); None if not, or if no route is left."""
        localizer, belief, params = self.localizer, self.belief, self.params
        twins = top_two_alike(belief, localizer.map.rooms, localizer.lookalike_groups)
        unsure = (target is None or twins) and _may_drive(belief, spent, params.max_targets)
        if not (
            unsure or _to_confirm(localizer, belief, self.visits, self.checks, params.max_targets)
        ):
            return None
        checked = Counter(done.room for done in self.checks)

        def first_route(tried: set[int]) -> tuple[Place, Route] | None:
            return route_to_check(
                localizer, belief, self.observation, tried, checked, params.routes, repeating
            )

        check = first_route(self.tried_routes)
        retry = {done.start for done in self.checks if not done.started} - self.retried_routes
        if check is None and unsure and retry:
            # a check that could not start told nothing, and the robot has moved on since:
            # its start once more (world seed 63's building: a robot in office_a whose
            # homings to office_b's two places gave up ended at 0.89 with drives left)
            self.retried_routes.update(retry)
            check = first_route(self.tried_routes - retry)
        if check is None and unsure and repeating:
            again = starts_to_check_again(self.checks, repeating, self._room_of)
            check = first_route(self.tried_routes - again)
        return check

    def drive_check(self, start: Place, route: Route, repeating: frozenset[str]) -> str | None:
        """Check ``start``'s room by ``route`` (:func:`~localizer.route_checks.check_route`)
        and look where the robot stands then."""
        localizer, robot, params = self.localizer, self.robot, self.params
        self.tried_routes.add(start.id)
        rival = likely_twin(self.belief, start.room, localizer.lookalikes)
        self.notify(localizer.belief(LocalizationState.HOMING))
        told = told_outcomes(telling_checks(self.checks, repeating, self._room_of), start.room)
        began = robot.odometry()
        done, captured, homing, homed_to = check_route(
            localizer, robot, self.go, start, route, rival, params.routes, params.homing, told
        )
        if not done.started and homed_to is None and homing.reason != CANCELLED:
            # the homing to the check's start gave up where it began: out of that corner
            # before the next check (world seed 63's building, two places per room: a
            # robot woken between a cabinet and the wall spent its four checks there)
            self.distance_m += _step_out(robot, self.observation, began, params) or 0.0
        localizer.predict(HOMING_STAY_PROBABILITY)
        self.observation, looked = _look_again(localizer, robot, homed_to)
        self.distance_m += done.distance_m
        self.frames += captured + looked
        self.belief = localizer.belief()
        self.notify(self.belief)
        self.checks.append(done)
        end_room = self._room_of(done.end)
        self.visits.append(Visit(done.end, end_room, homing, self.belief, done.started))
        return CANCELLED if homing.reason == CANCELLED else None

    def last_look(self, spent: int) -> int | None:
        """The place to home to for a last look before the loop ends, if any
        (:func:`~localizer.last_looks.closer_look`, then, with a drive left,
        :func:`~localizer.last_looks.place_to_end_at`); each once."""
        target = closer_look(self.localizer, self.looked_closer)
        if target is None and self.params.end_at_place and spent < self.params.max_targets:
            target = place_to_end_at(self.localizer, self.looked_closer)
        if target is not None:
            self.looked_closer.add(target)
        return target

    def step_in(self) -> bool:
        """Step further into the room the belief is ``localized`` in from the place recorded
        on the way in where the robot looked (:func:`~localizer.last_looks.way_in_step`) and
        look there; whether it did."""
        localizer, robot, params = self.localizer, self.robot, self.params
        if params.step_in_m <= 0:
            return False
        step_in = way_in_step(
            localizer, robot, params.step_in_m, params.homing.step, self.stepped_in
        )
        if step_in is None:
            return False
        frame, inside, captured = step_in
        self.frames += captured
        self.looked_closer.update(self.stepped_in)  # its room is looked at: do not home back
        self.notify(localizer.belief(LocalizationState.HOMING))
        here = frame.pose(robot.odometry())
        route = route_through((here.x_m, here.y_m), [inside])
        self.distance_m += drive_route(robot, route, frame).distance_m
        self._look_here()
        self.notify(self.belief)
        return True

    def drive_to(self, target: int) -> str | None:
        """Home to place ``target`` (and its counterparts on that spot are looked at from
        there), back to the place the robot stood at if that homing did not arrive, and look
        where the robot stands then, unless it is back where it looked last."""
        localizer, params = self.localizer, self.params
        self.context = self.context.trying(target)
        for same_spot in localizer.same_spot_places(target):  # looked at from there already
            self.context = self.context.trying(same_spot)
        self.notify(localizer.belief(LocalizationState.HOMING))
        stood_at = localizer.latest.at_place if localizer.latest is not None else None
        homing = self._home(target)
        looked_from: int | None = target
        cancelled = homing.reason == CANCELLED
        if not homing.arrived and not cancelled and stood_at is not None:
            # back to the place the robot stood at, as a check that cannot start comes back:
            # where the homing gave up may be another room (world seed 33's house, one place
            # per room: 3 of 20 robots homed from bathroom_a toward bathroom_b's place gave up
            # in the hall, and ended there while the belief was of bathroom_a)
            back = self._home(stood_at)
            looked_from = stood_at if back.arrived else None
            cancelled = back.reason == CANCELLED
        came_back = looked_from == stood_at != target
        if came_back:
            self.belief = localizer.belief()  # back where it looked last: no new evidence
        elif homing.distance_m >= params.min_new_view_m:
            self._look_here(looked_from)
        else:
            self.belief = localizer.belief()
        self.notify(self.belief)
        room = self._room_of(target)
        self.visits.append(Visit(target, room, homing, self.belief, not came_back))
        return CANCELLED if cancelled else None


def _look(localizer: Localizer, robot: Robot, at_place: int | None = None) -> Observation:
    """A frame captured where the robot stands, with the place it homed to (if any) and its
    odometry (frames from one spot count once: :data:`localizer.localizer.SAME_VIEW_M`)."""
    observation = localizer.observe(robot.capture().image)
    return replace(observation, at_place=at_place, odometry=robot.odometry())


def _look_again(
    localizer: Localizer, robot: Robot, at_place: int | None
) -> tuple[Observation, int]:
    """The observation to go on with where the robot stands (at place ``at_place``, if it
    homed to one), folded into the belief, and the frames captured for it: none if the robot
    looked from that place last (the same view is no new evidence)."""
    latest = localizer.latest
    if at_place is not None and latest is not None and latest.at_place == at_place:
        return latest, 0
    observation = _look(localizer, robot, at_place)
    localizer.update(observation)
    return observation, 1


def _drives_spent(visits: Sequence[Visit], max_targets: int) -> int:
    """The drives of ``visits`` that count against ``max_targets``: those that told something.
    Drives that told nothing (a check whose homing to its start place did not arrive, a drive
    to a place that did not arrive, each tried once) spend the budget only once there have been
    ``max_targets`` of them: on world seed 35's building (two places per room), 12 of 78
    checks could not start (homing ``converged`` half a metre on, or went out into the
    corridor), and 5 of the 7 robots that ended ambiguous at the drive limit had spent one to
    three of their four drives so (with this rule it ended the same: the drives left went to
    places whose frames weigh the twins alike)."""
    told = sum(1 for visit in visits if visit.told)
    return max_targets if len(visits) - told >= max_targets else told


def top_two_alike(
    belief: RoomBelief, rooms: Sequence[str], groups: Sequence[Sequence[int]]
) -> bool:
    """Whether the two most likely rooms of ``belief`` are in one group of look-alikes
    (``groups``: indices into ``rooms``, as :attr:`Localizer.lookalike_groups`, which the
    belief reads together): then a route check comes before the policy's place (a counterpart
    a few decimetres off its twin's spot favours the room it is nearer to: on world seed 12's
    building recorded on one drive, one place per room, the offices' places stood at nearly
    one spot and drives to them ended sure and wrong in 3 of 20 kidnappings). In a group of
    three, the top two need not be a pair: world seed 43's building (two places per room)
    paired office_b with a storage room as well as with office_a, the belief stayed a third
    each, and with storage on top and office_a second no route checked the offices (14 of 20
    kidnappings ended ambiguous)."""
    second = belief.second
    if second is None:
        return False
    top, other = rooms.index(belief.top[0]), rooms.index(second[0])
    return any(top in group and other in group for group in groups)


def _to_confirm(
    localizer: Localizer,
    belief: RoomBelief,
    visits: Sequence[Visit],
    checks: Sequence[RouteCheck],
    max_targets: int,
) -> bool:
    """Whether the most likely room is to be checked by a route before the belief is taken:
    it has one place and no known look-alike (:meth:`Localizer.alone`), no route checked it
    yet, a drive is left, and the belief is ``localized`` or the robot last homed to that
    place. A room of one place gives the calibration nothing to find its twin by, and from
    the twin's spot the frame is the place's own view; a route out of the room, driven from
    the twin, ends elsewhere (a house recorded one place per room, world seed 21: two robots
    in bedroom_b homed to bedroom_a's place and ended sure of bedroom_a)."""
    room = belief.top[0]
    if belief.state is LocalizationState.LOST or _drives_spent(visits, max_targets) >= max_targets:
        return False
    if not localizer.alone(room) or any(done.room == room for done in checks):
        return False
    homed_there = bool(visits) and visits[-1].room == room
    return belief.state is LocalizationState.LOCALIZED or homed_there


def _step_out(
    robot: Robot, observation: Observation, began: Pose2D, params: ActiveParams
) -> float | None:
    """:func:`~localizer.looking_elsewhere.step_away_if_stuck` with ``params``' lost-look
    settings: the metres stepped, or None when the robot was not stuck."""
    return step_away_if_stuck(
        robot, observation, began, params.lost_stuck_m, params.lost_step_m, params.lost_turn_deg
    )


def _may_drive(belief: RoomBelief, drives: int, max_targets: int) -> bool:
    return belief.state is LocalizationState.AMBIGUOUS and drives < max_targets


def _ending(belief: RoomBelief, drives: int, max_targets: int) -> str:
    """Why the loop stopped asking for a drive (see :func:`active_step`): a key of
    :data:`ENDINGS`."""
    if belief.state is LocalizationState.LOST:
        return "lost"
    if belief.state is not LocalizationState.AMBIGUOUS:
        return "settled"
    return "drive-limit" if drives >= max_targets else "no-telling-place"
