"""Running toploc as a service: the nodes of one robot on one Zenoh session.

:func:`start_service` opens the session and declares the map node, the localizer node, the
homing node (:mod:`toploc.nodes.homing`; the active localizer drives through it) and,
when a robot object is given (the simulated robot here), its robot node. The localizer always
drives the robot through the bus (:class:`toploc.nodes.robot.RemoteRobot`), so a real base
running its own robot node elsewhere is used the same way.

Each node role has its ``enter_*`` function (robot, camera, localizer with homing, map, the ROS 2
bridge), which
enters the node into an :class:`~contextlib.ExitStack`: ``toploc serve`` enters several on one
session, ``toploc node ROLE`` one per process (:mod:`toploc.commands.node`).

A map that grows over the bus (``map/add``, ``map/connect``: the map node publishes
``map/changed``) is picked up without a restart by :class:`MapRefresher`: once no change came
for ``settle_s`` seconds it re-reads the map and swaps it into the localizer between two
localizations (the next one uses the new places), then, if asked, re-calibrates the likelihood
on the grown map (about 20 s per detector here) and swaps the map in again with it.

With ``allow_empty`` a map without places is served too (a user about to record one): the
localizer keys answer "the map has no places yet" until the first places are recorded.

toploc's built-in world map (the demo's, served when no map is named: ``builtin_map``) is never
written through the bus: ``map/add`` and ``map/connect`` reply with :data:`BUILTIN_MAP_REFUSAL`.

A robot of a site (``map_from``: a site map's id, docs/site.md) localizes on a replica of
that map, ``db_path`` a file of its own: :class:`~toploc.replication.MapReplicator` keeps it
current and hands each update to the :class:`MapRefresher`; the robot's ``map/*`` keys read
the replica and pass writes on to the site map's node; each belief carries ``map_age_s``.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

import zenoh

from localizer.features import params_from_preset
from localizer.localizer import Localizer, LocalizerConfig
from localizer.robot_protocol import Camera, Robot
from mapdb.database import MapDatabase
from mapdb.errors import ReplicaError
from mapdb.loading import open_for_reading
from toploc import bus
from toploc.bus import BusConfig, open_session
from toploc.bus.clients.site_map import subscribe_site_changes
from toploc.limits import Limits
from toploc.maps import calibrate_map, load_map
from toploc.nodes.camera import CameraNode
from toploc.nodes.homing import HomingNode, HomingService
from toploc.nodes.localizer import LocalizerNode
from toploc.nodes.mapdb import MapNode, subscribe_changes
from toploc.nodes.robot import RemoteRobot, RobotNode
from toploc.nodes.ros2 import Ros2Bridge, Ros2Settings
from toploc.replication import MapReplicator
from toploc.runner import LocalizationRunner

REFRESH_SETTLE_S = 2.0
REFRESH_MAX_DELAY_S = 5.0
"""The longest a change waits for its refresh while others keep coming (several robots adding
places at once would otherwise never leave ``settle_s`` without a change)."""
REPLICA_WAIT_S = 10.0
"""How long a site robot's service waits at start for its replica to be current."""
BUILTIN_MAP_REFUSAL = (
    "{db} is toploc's built-in map of a rendered world (the demo's), which the bus does not "
    "write to: to record your own map, serve one with toploc serve --db FILE --new-map (or "
    "--db FILE for a map you have); nothing was written"
)
"""The error reply of ``map/add`` and ``map/connect`` on the built-in map (``{db}``: its path)."""
_log = logging.getLogger(__name__)


class MapRefresher:
    """Reload the map at ``db_path`` into ``runner`` after changes settle (a thread of its own).

    :meth:`changed` (called for each ``map/changed`` the map node publishes) restarts the
    ``settle_s`` wait (but a change waits ``max_delay_s`` at most, however many follow it);
    when it ends the map is re-read (``detector``) and swapped in
    (:meth:`LocalizationRunner.replace_map`); with ``recalibrate``, each detector the map
    holds (``detector`` first) is then calibrated and the map swapped in again with its new
    likelihood. A change during the calibration starts another round when it ends. Errors are
    logged; the old map stays. Without a ``runner`` (a site map's node, which localizes
    nothing) it only re-calibrates.
    """

    def __init__(
        self,
        db_path: Path,
        runner: LocalizationRunner | None,
        detector: str = "sift",
        settle_s: float = REFRESH_SETTLE_S,
        recalibrate: bool = True,
        max_delay_s: float = REFRESH_MAX_DELAY_S,
    ) -> None:
        self.db_path = db_path
        self.runner = runner
        self.detector = detector
        self.settle_s = settle_s
        self.max_delay_s = max(max_delay_s, settle_s)
        self._pending_since_s: float | None = None
        self.recalibrate = recalibrate
        self.reloads = 0  # maps swapped in so far (the version the log names)
        self._lock = threading.Lock()
        self._changes = 0
        self._done = 0
        self._last_change_s = 0.0
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._idle = threading.Condition(self._lock)
        self._thread = threading.Thread(target=self._run, name="map-refresh", daemon=True)
        self._thread.start()

    def changed(self) -> None:
        """The map was written: refresh once no change came for ``settle_s``."""
        with self._lock:
            self._changes += 1
            self._last_change_s = time.monotonic()
            if self._pending_since_s is None:
                self._pending_since_s = self._last_change_s
        self._wake.set()

    def wait_idle(self, timeout_s: float) -> bool:
        """Wait until every change so far is refreshed (and calibrated if asked); whether it
        was within ``timeout_s``."""
        with self._idle:
            return self._idle.wait_for(lambda: self._done >= self._changes, timeout_s)

    def close(self, wait_s: float = 1.0) -> None:
        """Stop the thread (a calibration in progress finishes on its own, in the background)."""
        self._stop.set()
        self._wake.set()
        self._thread.join(wait_s)

    @property
    def running(self) -> bool:
        """Whether its thread still runs (after :meth:`close`: a calibration finishing)."""
        return self._thread.is_alive()

    def _settled(self) -> int | None:
        """Wait for ``settle_s`` without a change; the number of changes then (None: stop)."""
        while True:
            with self._lock:
                due_s = self._last_change_s + self.settle_s
                if self._pending_since_s is not None:
                    due_s = min(due_s, self._pending_since_s + self.max_delay_s)
                remaining_s = due_s - time.monotonic()
                changes = self._changes
                if remaining_s <= 0:
                    self._pending_since_s = None  # changes from now on wait anew
            if remaining_s <= 0:
                return changes
            if self._stop.wait(remaining_s):
                return None

    def _run(self) -> None:
        while not self._stop.is_set():
            self._wake.wait()
            self._wake.clear()
            with self._lock:
                if self._done >= self._changes:  # woken by changes the last round included
                    continue
            changes = self._settled()
            if changes is None:
                return
            try:
                self._refresh()
            except Exception as error:  # the service goes on with the map it has
                _log.warning("map refresh of %s failed: %s", self.db_path, error)
            with self._idle:
                self._done = max(self._done, changes)
                self._idle.notify_all()

    def _refresh(self) -> None:
        detector = params_from_preset(self.detector).detector
        if self.runner is not None:
            loaded = load_map(self.db_path, self.detector)
            if not self.runner.replace_map(loaded):
                return
            self.reloads += 1
            _log.info(
                "map %s reloaded (version %d since start): %d places, %d rooms", self.db_path,
                self.reloads, len(loaded.places), len(loaded.rooms),
            )  # fmt: skip
        if not self.recalibrate:
            return
        with MapDatabase.open(self.db_path, create=False, readonly=True) as map_db:
            held = sorted(map_db.fingerprint_counts(), key=lambda d: d != detector)
        for name in held:
            if self._stop.is_set():
                return
            start_s = time.monotonic()
            calibrate_map(self.db_path, name)
            _log.info(
                "map %s: %s likelihood re-calibrated in %.1f s", self.db_path, name,
                time.monotonic() - start_s,
            )  # fmt: skip
            if name == detector and self.runner is not None:
                self.runner.replace_map(load_map(self.db_path, self.detector))


@dataclass(frozen=True)
class Service:
    """A running service: its session, the runner behind ``localizer/*``, the map (as first
    loaded; None for a map without places) and what keeps it fresh."""

    session: zenoh.Session
    config: BusConfig
    runner: LocalizationRunner
    localizer: Localizer | None
    refresher: MapRefresher
    homing: HomingService | None = None
    replicator: MapReplicator | None = None
    """A site robot's replica keeper (``map_from``), else None."""


@dataclass(frozen=True)
class LocalizerNodes:
    """What :func:`enter_localizer_nodes` runs: the runner behind ``localizer/*``, the map as
    first loaded (None for a map without places), what keeps it fresh, the homing service."""

    runner: LocalizationRunner
    localizer: Localizer | None
    refresher: MapRefresher
    homing: HomingService
    replicator: MapReplicator | None = None
    """A site robot's replica keeper (``map_from``), else None."""


def enter_robot_node(
    stack: ExitStack,
    session: zenoh.Session,
    robot_id: str,
    robot: Robot,
    limits: Limits,
    camera: Camera | None = None,
    serve_camera: bool = True,
) -> RobotNode:
    """The robot node of ``robot`` (``toploc node robot``), its camera ``camera`` (None: the
    robot's own; ``serve_camera`` false: none, a camera node serves the captures)."""
    return stack.enter_context(RobotNode(session, robot_id, robot, limits, camera, serve_camera))


def enter_camera_node(
    stack: ExitStack, session: zenoh.Session, robot_id: str, camera: Camera, limits: Limits
) -> CameraNode:
    """A camera node without a base (``toploc node camera``)."""
    return stack.enter_context(CameraNode(session, robot_id, camera, limits))


def enter_localizer_nodes(
    stack: ExitStack,
    session: zenoh.Session,
    robot_id: str,
    db_path: Path,
    policy: str = "separating",
    localizer_config: LocalizerConfig | None = None,
    limits: Limits | None = None,
    refresh_settle_s: float = REFRESH_SETTLE_S,
    recalibrate: bool = True,
    allow_empty: bool = False,
    map_from: str | None = None,
) -> LocalizerNodes:
    """The localizer and homing nodes on the map at ``db_path`` (``toploc node localizer``),
    driving the bus's robot node (:class:`RemoteRobot`). The map is reloaded after each
    ``map/changed`` of the robot id's map node, in this process or another (one mechanism for
    both; the map node publishes it before its reply, and a session delivers its own
    publications to its subscribers at once). On exit a running localization is ended first.
    ``map_from``: a site map's id; ``db_path`` is then this robot's replica of it (made or
    brought up to date first, :func:`enter_replica`), reloaded after each update the replica
    takes (published as the robot's ``map/changed``, ``what`` ``replica``), with the likelihood
    that comes with the map (no ``recalibrate``); each belief carries the replica's
    ``map_age_s``.
    """
    localizer_config = localizer_config or LocalizerConfig()
    limits = limits or Limits()
    replicator = None
    map_age: Callable[[], float | None] | None = None
    if map_from is not None:
        replicator = enter_replica(stack, session, map_from, db_path, robot_id=robot_id)
        recalibrate, allow_empty, map_age = False, True, replicator.map_age_s
    localizer = None
    if not (allow_empty and _has_no_places(db_path)):
        localizer = Localizer(load_map(db_path, localizer_config.detector), localizer_config)
    remote = RemoteRobot(
        session, robot_id, move_timeout_s=limits.move_timeout_s + bus.DEFAULT_TIMEOUT_S,
        max_image_pixels=limits.max_image_pixels,
    )  # fmt: skip
    stack.callback(remote.close)
    runner = LocalizationRunner(
        localizer, remote, policy, max_pending=limits.max_pending_localizations,
        localizer_config=localizer_config,
    )  # fmt: skip
    node = stack.enter_context(LocalizerNode(session, robot_id, runner, limits, map_age))
    runner.publish = node.publish
    homing = HomingService(runner)  # homing/*; also how an active localization drives
    homing.publish = stack.enter_context(HomingNode(session, robot_id, homing, limits)).publish
    runner.home = homing.home
    stack.callback(runner.stop)  # on exit, before the nodes above close: a run ends
    refresher = MapRefresher(
        db_path, runner, localizer_config.detector, refresh_settle_s, recalibrate
    )
    stack.callback(refresher.close)
    stack.callback(subscribe_changes(session, robot_id, refresher.changed).undeclare)
    if replicator is not None:  # its updates reach the refresher as the robot's map/changed
        replicator.start()
    return LocalizerNodes(runner, localizer, refresher, homing, replicator)


def enter_map_node(
    stack: ExitStack,
    session: zenoh.Session,
    robot_id: str,
    db_path: Path,
    limits: Limits,
    localizer_config: LocalizerConfig | None = None,
    refresh_settle_s: float = REFRESH_SETTLE_S,
    builtin_map: bool = False,
    map_id: str | None = None,
    forward_to: str | None = None,
) -> MapNode:
    """The map node of ``db_path`` (``toploc node map``); ``map/add`` reads panoramas with the
    localizer's camera model and extracts its detector into an empty map. ``builtin_map``:
    ``db_path`` is toploc's own world map, which the node refuses to write. ``map_id``: serve
    it as that site map (``toploc/map/<map_id>/``); ``forward_to``: ``db_path`` is a replica of
    that site map, whose node takes the writes."""
    localizer_config = localizer_config or LocalizerConfig()
    read_only = BUILTIN_MAP_REFUSAL.format(db=db_path) if builtin_map else None
    return stack.enter_context(
        MapNode(
            session, robot_id, db_path, limits, str(localizer_config.camera),
            detectors=(localizer_config.detector,), refresh_after_s=refresh_settle_s,
            read_only=read_only, map_id=map_id, forward_to=forward_to,
        )
    )  # fmt: skip


def enter_site_calibration(
    stack: ExitStack,
    session: zenoh.Session,
    map_id: str,
    db_path: Path,
    detector: str = "sift",
    settle_s: float = REFRESH_SETTLE_S,
) -> MapRefresher:
    """Re-calibrate site map ``map_id``'s likelihood at ``db_path`` after its writes settle (as
    ``toploc serve`` does after its own), on the map host; the new likelihood is a write, so
    every replica gets it."""
    refresher = MapRefresher(db_path, None, detector, settle_s, recalibrate=True)
    stack.callback(refresher.close)
    changed = refresher.changed
    stack.callback(subscribe_site_changes(session, map_id, lambda _v: changed()).undeclare)
    return refresher


def enter_replica(
    stack: ExitStack,
    session: zenoh.Session,
    map_id: str,
    replica_path: Path,
    wait_s: float = REPLICA_WAIT_S,
    robot_id: str | None = None,
) -> MapReplicator:
    """The replica of site map ``map_id`` at ``replica_path``, brought up to date first (up to
    ``wait_s``; a robot whose link is down starts on the replica it has); each later update is
    published as robot ``robot_id``'s ``map/changed``. Raises
    :class:`~mapdb.errors.ReplicaError` for a replica refused, and for none at all while the map
    node cannot be reached."""
    replicator = MapReplicator(session, map_id, replica_path, robot_id=robot_id)
    stack.callback(replicator.close)
    if not replicator.wait_current(wait_s):
        state = replicator.state()
        if state is None or (replicator.error or "").startswith(f"replica {replica_path}"):
            raise ReplicaError(
                str(replicator.error) if state is not None
                else f"no replica of map {map_id} at {replica_path} yet and its map node did not "
                f"answer within {wait_s:g} s ({replicator.error}): start once with the link up",
                replica_path,
            )  # fmt: skip
        _log.warning(
            "map %s not reached (%s): localizing from replica %s at version %d", map_id,
            replicator.error, replica_path, state.version,
        )  # fmt: skip
    return replicator


def enter_ros2_bridge(
    stack: ExitStack,
    toploc_session: zenoh.Session,
    robot_id: str,
    ros_config: BusConfig,
    settings: Ros2Settings,
) -> Ros2Bridge:
    """The ROS 2 bridge of ``robot_id``'s localizer (``toploc node ros2``, ``toploc serve
    --ros2``) on a session of its own, ``ros_config``: a peer of the ROS router."""
    ros_session = stack.enter_context(open_session(ros_config))
    return stack.enter_context(Ros2Bridge(toploc_session, robot_id, ros_session, settings))


@contextmanager
def start_service(
    db_path: Path,
    config: BusConfig,
    robot: Robot | None = None,
    policy: str = "separating",
    localizer_config: LocalizerConfig | None = None,
    limits: Limits | None = None,
    camera: Camera | None = None,
    refresh_settle_s: float = REFRESH_SETTLE_S,
    recalibrate: bool = True,
    allow_empty: bool = False,
    builtin_map: bool = False,
    map_from: str | None = None,
    map_id: str | None = None,
) -> Iterator[Service]:
    """Serve the map at ``db_path`` for robot ``config.robot_id`` within ``limits``; the
    robot node (when ``robot`` is given) captures from ``camera`` if given, else the robot.

    Places and edges added over the bus are used ``refresh_settle_s`` after the last change;
    ``recalibrate`` then fits the likelihood again (:class:`MapRefresher`). ``allow_empty``:
    serve a map without places (else :class:`mapdb.errors.EmptyMapError`). ``builtin_map``:
    ``db_path`` is toploc's own world map, never written over the bus. On exit a running
    localization is ended (at its next capture or move), then everything is undeclared and the
    session closed (an unclosed session keeps the process alive). The nodes are those of
    ``toploc node robot``, ``localizer`` and ``map`` (the ``enter_*`` functions), on one session.
    ``map_from``: a site map's id; ``db_path`` is then this robot's replica of it (made or
    brought up to date first, :func:`enter_replica`), kept current after. ``map_id``: also
    serve the map at ``db_path`` as that site map (the map host is a robot too); its localizer
    refreshes after the site map's writes as after its own.
    """
    localizer_config = localizer_config or LocalizerConfig()
    limits = limits or Limits()
    robot_id = config.robot_id
    with ExitStack() as stack:
        session = stack.enter_context(open_session(config))
        if robot is not None:
            enter_robot_node(stack, session, robot_id, robot, limits, camera)
        nodes = enter_localizer_nodes(
            stack, session, robot_id, db_path, policy, localizer_config, limits,
            refresh_settle_s, recalibrate, allow_empty, map_from,
        )  # fmt: skip
        # last: a place added as soon as it answers is refreshed too
        enter_map_node(
            stack, session, robot_id, db_path, limits, localizer_config, refresh_settle_s,
            builtin_map, forward_to=map_from,
        )  # fmt: skip
        if map_id is not None:
            changed = nodes.refresher.changed
            stack.callback(subscribe_site_changes(session, map_id, lambda _v: changed()).undeclare)
            enter_map_node(
                stack, session, robot_id, db_path, limits, localizer_config, refresh_settle_s,
                map_id=map_id,
            )  # fmt: skip
        yield Service(
            session, config, nodes.runner, nodes.localizer, nodes.refresher, nodes.homing,
            nodes.replicator,
        )  # fmt: skip


def _has_no_places(db_path: Path) -> bool:
    with open_for_reading(db_path) as map_db:
        return not map_db.places()
