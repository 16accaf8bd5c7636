"""The localization service: one localizer, one robot, a belief that clients can ask for.

:class:`LocalizationRunner` is what :class:`toploc.nodes.localizer.LocalizerNode` serves on the bus
(it knows nothing of Zenoh). Zenoh answers each query on its own thread, so the runner is
thread-safe: one localization at a time (a second waits), ``belief()`` always answers at once
with the latest snapshot, and ``reset()`` during a run is refused with a clear error rather
than changing the belief under the running loop.

A waiting localization whose client has given up (its ``deadline_s`` passed) is dropped before
it runs, and at most ``max_pending`` wait. ``stop()`` ends a running localization at its next
capture or move (within about one feature extraction) and refuses new ones: what a service
does on SIGTERM.

A service may start on a map without places (a user about to record one): the runner then has
no localizer, and ``belief``, ``localize`` and ``reset`` raise :class:`NoPlacesYetError` until
the first :meth:`LocalizationRunner.replace_map` brings places.

The robot is held by one thing at a time: a localization, or (:meth:`LocalizationRunner.driving`)
a homing goal of :mod:`toploc.nodes.homing`, which is refused at once while a localization runs
and makes a localization wait for its turn while it drives; ``stop()`` ends it the same way.
An active localization drives to its targets with ``home`` when set (the homing node's, so its
drives publish progress and can be cancelled), else with ``drive_home``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import replace
from typing import Any

from localizer.active import ActiveParams, ActiveResult, localize_actively
from localizer.belief import RoomBelief
from localizer.loaded_map import LoadedMap
from localizer.localizer import Localizer, LocalizerConfig
from localizer.robot_protocol import Capture, MoveResult, Pose2D, Robot
from localizer.visual_homing import HomingResult

RESET_WAIT_S = 1.0
_log = logging.getLogger(__name__)
POLL_S = 0.1  # how often a waiting localization looks at its deadline and at stop()
ODOMETRY_RETRY_S = 60.0
"""After the robot gave no odometry (a camera alone on the bus: each query times out), passive
localizations go without it for this long, in seconds, before asking again."""


class LocalizationStoppedError(RuntimeError):
    """The service is stopping: the localization was ended, or not started."""


class NoPlacesYetError(RuntimeError):
    """The service's map has no places yet: nothing to localize against."""


NO_PLACES_YET = "the map has no places yet: record some first (toploc map record)"


class LocalizationDroppedError(TimeoutError):
    """A localization was not run: its client gave up while it waited, or too many wait."""


class RobotBusyError(RuntimeError):
    """The robot is held by a running localization or homing goal."""


class StoppableRobot:
    """``robot``, but every capture and move first checks ``stopping`` and raises
    :class:`LocalizationStoppedError` once it is set (the loop then unwinds at once)."""

    def __init__(self, robot: Robot, stopping: threading.Event) -> None:
        self.robot = robot
        self.stopping = stopping

    def _check(self) -> None:
        if self.stopping.is_set():
            raise LocalizationStoppedError("the service is stopping")

    def capture(self) -> Capture:
        self._check()
        return self.robot.capture()

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        self._check()
        return self.robot.move(turn_rad, forward_m)

    def odometry(self) -> Pose2D:
        return self.robot.odometry()

    def stop(self) -> None:
        self.robot.stop()


class LocalizationRunner:
    """Localize ``robot`` against ``localizer``'s map on request; publish every new belief.

    ``publish`` is called with each belief message (e.g. ``LocalizerNode.publish``); it may be
    set after construction, since the node needs the runner first; so may ``home`` (how an
    active localization drives to a place, see the module docstring). ``localizer`` None: the
    map has no places yet; the first :meth:`replace_map` makes one with ``localizer_config``.
    """

    def __init__(
        self,
        localizer: Localizer | None,
        robot: Robot,
        policy: str = "separating",
        params: ActiveParams | None = None,
        publish: Callable[[dict[str, Any]], object] | None = None,
        max_pending: int = 8,
        localizer_config: LocalizerConfig | None = None,
        home: Callable[[int], HomingResult] | None = None,
    ) -> None:
        self._localizer = localizer
        self.localizer_config = localizer_config
        self.home = home
        self._stopping = threading.Event()
        self.robot = StoppableRobot(robot, self._stopping)
        self.max_pending = max_pending
        self._pending = 0
        self._odometry_retry_s = 0.0  # monotonic s: passive looks go without odometry until
        self._pending_lock = threading.Lock()
        self.policy = policy
        self.params = params or ActiveParams()
        self.publish = publish
        self._run_lock = threading.Lock()
        self._snapshot_lock = threading.Lock()
        self._latest = None if localizer is None else localizer.belief().to_json()

    @property
    def localizer(self) -> Localizer:
        """The localizer; :class:`NoPlacesYetError` while the map has no places."""
        if self._localizer is None:
            raise NoPlacesYetError(NO_PLACES_YET)
        return self._localizer

    def _set(self, belief: RoomBelief) -> None:
        message = belief.to_json()
        with self._snapshot_lock:
            self._latest = message
        if self.publish is not None:
            self.publish(message)

    def belief(self) -> dict[str, Any]:
        """The latest belief (answers at once, also while a localization runs)."""
        with self._snapshot_lock:
            latest = self._latest
        if latest is None:
            raise NoPlacesYetError(NO_PLACES_YET)
        return dict(latest)

    def _wait_for_turn(self, deadline_s: float | None) -> None:
        """Take the run lock, or raise: stopping, or ``deadline_s`` (``time.monotonic()``)
        passed while waiting, or ``max_pending`` already wait."""
        with self._pending_lock:
            if self._pending >= self.max_pending:
                raise LocalizationDroppedError(
                    f"refused: {self._pending} localizations are already waiting "
                    f"(at most {self.max_pending})"
                )
            self._pending += 1
        try:
            while not self._run_lock.acquire(timeout=POLL_S):
                if self._stopping.is_set():
                    raise LocalizationStoppedError("the service is stopping")
                if deadline_s is not None and time.monotonic() > deadline_s:
                    raise LocalizationDroppedError(
                        "dropped: the client's timeout passed while it waited for its turn"
                    )
        finally:
            with self._pending_lock:
                self._pending -= 1
        if self._stopping.is_set():
            self._run_lock.release()
            raise LocalizationStoppedError("the service is stopping")
        if deadline_s is not None and time.monotonic() > deadline_s:
            self._run_lock.release()
            raise LocalizationDroppedError(
                "dropped: the client's timeout passed while it waited for its turn"
            )

    def localize(self, active: bool, deadline_s: float | None = None) -> dict[str, Any]:
        """Capture and update the belief; with ``active``, start from a uniform belief and drive
        to disambiguate while it is ambiguous (this takes a while). Without, one frame with the
        robot's odometry, folded in as a passive one (:meth:`localizer.localizer.Localizer.
        update`: a frame of the latest view replaces its evidence, one of a new view is folded
        in after the belief is spread).

        ``deadline_s`` (``time.monotonic()``): when the client stops waiting; a localization
        still waiting for its turn then is dropped (:class:`LocalizationDroppedError`).
        :class:`LocalizationStoppedError` after :meth:`stop`.
        """
        localizer = self.localizer  # NoPlacesYetError at once, not after waiting
        self._wait_for_turn(deadline_s)
        start_s = time.monotonic()
        summary: dict[str, Any] | None = None
        try:
            localizer = self.localizer  # replaced while this one waited
            if active:
                result = localize_actively(
                    localizer,
                    self.robot,
                    self.policy,
                    self.params,
                    on_belief=self._set,
                    home=self.home,
                )
                belief = result.final
                summary = active_summary(result)
            else:
                observation = localizer.observe(self.robot.capture().image)
                observation = replace(observation, odometry=self._odometry())
                belief = localizer.update(observation, passive=True)
            self._set(belief)
            _log_localization(belief, time.monotonic() - start_s, summary)
            return self.belief() | ({"active": summary} if summary is not None else {})
        finally:
            self._run_lock.release()

    def _odometry(self) -> Pose2D | None:
        """The robot's odometry for a passive look, by which requests from one spot count once
        (:data:`localizer.localizer.SAME_VIEW_M`). None from a robot that gives none (a camera
        alone on the bus: its odometry query times out), logged when it stops and when it comes
        back, and not asked again for :data:`ODOMETRY_RETRY_S`; whether two frames were taken on
        one spot is then told by the images (:func:`localizer.visual_homing.same_spot`)."""
        now_s = time.monotonic()
        if now_s < self._odometry_retry_s:
            return None
        try:
            odometry = self.robot.odometry()
        except LocalizationStoppedError:
            raise
        except Exception as error:  # a base fault of any kind: the look goes on without
            if self._odometry_retry_s == 0.0:
                _log.warning(
                    "no odometry from the robot (%s): whether it moved between two passive "
                    "localizations is told by their images, for the next %.0f s at least",
                    error,
                    ODOMETRY_RETRY_S,
                )
            self._odometry_retry_s = now_s + ODOMETRY_RETRY_S
            return None
        if self._odometry_retry_s:
            _log.info("odometry from the robot again")
            self._odometry_retry_s = 0.0
        return odometry

    @contextmanager
    def driving(self) -> Iterator[StoppableRobot]:
        """Hold the robot for something else than a localization (a homing goal) and yield it:
        at once, or :class:`RobotBusyError` while a localization (or another holder) runs;
        :class:`LocalizationStoppedError` after :meth:`stop`, whose robot raises it at the next
        capture or move as during a localization."""
        if not self._run_lock.acquire(blocking=False):
            raise RobotBusyError("busy: a localization is running; try again when it has ended")
        try:
            if self._stopping.is_set():
                raise LocalizationStoppedError("the service is stopping")
            yield self.robot
        finally:
            self._run_lock.release()

    def stop(self, wait_s: float = 2.0) -> bool:
        """End the running localization at its next capture or move, refuse new ones, and wait
        up to ``wait_s`` seconds for it to end; whether it did.

        The base is told to stop again every ``POLL_S`` while the localization holds the robot:
        a move that passed its stopping check just before the first stop clears the base's stop
        when it starts (a base cannot tell a stop meant for the move it is starting from an old
        one), and the next stop ends it.
        """
        self._stopping.set()
        deadline_s = time.monotonic() + wait_s
        while self._run_lock.locked():
            try:
                self.robot.stop()  # a move in progress returns early
            except Exception as error:  # stopping must go on whatever the base says
                _log.warning("could not stop the robot: %s", error)
            remaining_s = deadline_s - time.monotonic()
            if remaining_s <= 0:
                return False
            if self._run_lock.acquire(timeout=min(POLL_S, remaining_s)):
                self._run_lock.release()
                return True
        return True

    def replace_map(self, loaded: LoadedMap) -> bool:
        """Swap in ``loaded`` (the map re-read after it grew) between localizations: waits for a
        running one to end, so the next one uses the new places; publishes the belief. False if
        the service stopped first."""
        while not self._run_lock.acquire(timeout=POLL_S):
            if self._stopping.is_set():
                return False
        try:
            if self._stopping.is_set():
                return False
            if self._localizer is None:  # the first places of a map that had none
                self._localizer = Localizer(loaded, self.localizer_config)
                self._set(self._localizer.belief())
            else:
                self._set(self._localizer.replace_map(loaded))
        finally:
            self._run_lock.release()
        return True

    def reset(self, prior: Mapping[str, float] | None) -> dict[str, Any]:
        """Uniform belief, or ``prior``; ``RuntimeError`` while a localization is running."""
        if self._stopping.is_set():
            raise LocalizationStoppedError("the service is stopping")
        self.localizer  # noqa: B018 (NoPlacesYetError while the map has none)
        if not self._run_lock.acquire(timeout=RESET_WAIT_S):
            raise RuntimeError("a localization is running; reset when it has finished")
        try:
            self._set(self.localizer.reset(prior))
        finally:
            self._run_lock.release()
        _log.info("belief reset to %s", "uniform" if prior is None else f"the prior {dict(prior)}")
        return self.belief()


def active_summary(result: ActiveResult) -> dict[str, Any]:
    """What a client is told of an active localization beside its belief (the ``active``
    field of the ``localizer/localize`` reply): drives, distance (odometric, metres) and why
    it ended (a key of :data:`localizer.active.ENDINGS`)."""
    return {
        "drives": len(result.visits),
        "distance_m": round(result.distance_m, 3),
        "ended": result.ended,
    }


def describe_active(summary: Mapping[str, Any]) -> str:
    """:func:`active_summary` in words for a log line or a ROS 2 Trigger message:
    ``2 drives, 1.66 m, ended: settled``."""
    return f"{summary['drives']} drives, {summary['distance_m']:.2f} m, ended: {summary['ended']}"


def _log_localization(
    belief: RoomBelief, elapsed_s: float, summary: Mapping[str, Any] | None = None
) -> None:
    """One INFO line per localization: its kind, state, top room and probability, the best
    place's inliers and how long it took (milliseconds, from its turn to its belief); for an
    active one also its drives, distance and why it ended."""
    room, probability = belief.top
    active = "" if summary is None else f", {describe_active(summary)}"
    _log.info(
        "localization (%s): %s, top %s %.3f, %s inliers, %.0f ms%s",
        "passive" if summary is None else "active",
        belief.state,
        room,
        probability,
        belief.best_place_inliers or 0,
        1000 * elapsed_s,
        active,
    )
