"""A robot's replica of a site's shared map, kept current over the bus (issue 22, docs/site.md).

:class:`MapReplicator` holds the replica file (a map file of the robot's own,
:mod:`mapdb.replica`) of site map ``map_id``: the first time it copies the map node's
snapshot; after that it asks for the changes after its version, whenever the map node's
``changed`` names a newer version and every ``poll_s`` seconds (what catches up a robot whose
link was down, or that missed a ``changed``). After each update it publishes the robot's own
``toploc/<robot_id>/map/changed`` (``what``: ``replica``), as a map node does after a write, so
everything that follows the robot's map (its localizer's :class:`~toploc.service.MapRefresher`,
the ROS 2 bridge's place cache, any client) hears of places other robots added; then it calls
``on_updated`` if given.

While the map node cannot be reached the robot localizes from the replica as it is;
:meth:`MapReplicator.map_age_s` (the belief's ``map_age_s``) is the seconds since the replica
last confirmed it was the map's current version. A replica of another map or one ahead of the
map node is refused (:class:`~mapdb.errors.ReplicaError`): logged, kept as it is, never merged.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import zenoh

from mapdb.errors import MapDatabaseError, ReplicaError
from mapdb.replica import ReplicaState, apply_changes, check_same_map, replica_state, write_snapshot
from mapdb.replication import BadMapDataError, decode_changes
from toploc import bus
from toploc.bus.clients.site_map import SiteMapClient, subscribe_site_changes
from toploc.bus.schemas import CHANGED

POLL_S = 2.0
"""How often a replica asks the map node for its version (and catches up)."""
QUERY_TIMEOUT_S = 3.0
_log = logging.getLogger(__name__)


class MapReplicator:
    """Keep the replica at ``path`` of site map ``map_id`` current over ``session``.

    :meth:`sync` runs one round in the caller's thread; :meth:`start` runs rounds on a thread
    of its own until :meth:`close`. ``robot_id``: the robot whose ``map/changed`` each update
    is published on (None: published on none).
    """

    def __init__(
        self,
        session: zenoh.Session,
        map_id: str,
        path: Path,
        on_updated: Callable[[], None] | None = None,
        poll_s: float = POLL_S,
        timeout_s: float = QUERY_TIMEOUT_S,
        robot_id: str | None = None,
    ) -> None:
        self.map_id = bus.check_map_id(map_id)
        self.path = Path(path)
        self.on_updated = on_updated
        self.poll_s = poll_s
        self.client = SiteMapClient(session, map_id, timeout_s)
        self.updates = 0  # rounds that changed the replica
        self.error: str | None = None  # the last refusal or failure, None when current
        self._confirmed_s: float | None = None  # time.monotonic() of the last confirmation
        self._round = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._entities: list[Any] = [subscribe_site_changes(session, map_id, self._on_changed)]
        self._publisher: zenoh.Publisher | None = None
        if robot_id is not None:
            self._publisher = session.declare_publisher(bus.key(robot_id, bus.MAP_CHANGED))
            self._entities.append(self._publisher)

    def state(self) -> ReplicaState | None:
        """The replica's map id and version; None before its first snapshot."""
        return replica_state(self.path)

    def map_age_s(self) -> float | None:
        """Seconds since the replica last confirmed it was the map's current version; None if
        it never did."""
        confirmed_s = self._confirmed_s
        return None if confirmed_s is None else time.monotonic() - confirmed_s

    def _on_changed(self, version: int | None) -> None:
        self._wake.set()

    def sync(self) -> bool:
        """One round: ask the map node for its version, then copy its snapshot (no replica
        yet) or apply the changes after the replica's version; whether the replica changed.

        Raises :class:`~toploc.bus.BusError` when the map node does not answer,
        :class:`~mapdb.errors.ReplicaError` for a replica or data refused (the replica is left
        as it was)."""
        with self._round:
            started_s = time.monotonic()
            version = self.client.version()
            state = self.state()
            changed = False
            if state is None:
                data, _ = self.client.snapshot()
                state = write_snapshot(self.path, data, self.map_id)
                _log.info("replica %s of map %s made at version %d", self.path, self.map_id,
                          state.version)  # fmt: skip
                changed = True
            check_same_map(self.path, state, self.map_id, version)
            while state.version < version:
                data, version, more = self.client.changes(state.version)
                try:
                    _, changes = decode_changes(data)
                except BadMapDataError as error:
                    raise ReplicaError(f"replica {self.path}: changes refused: {error}") from None
                if not changes:
                    break
                state = apply_changes(self.path, self.map_id, changes)
                changed = True
                if not more and state.version >= version:
                    break
            if state.version >= version:
                self._confirmed_s = started_s
            self.error = None
        if changed:
            self.updates += 1
            _log.info("replica %s at version %d", self.path, state.version)
            if self._publisher is not None:
                message = {"what": "replica", "stamp": time.time(), "version": state.version,
                           "map_id": self.map_id}  # fmt: skip
                self._publisher.put(CHANGED.encode(message))
            if self.on_updated is not None:
                self.on_updated()
        return changed

    def wait_current(self, timeout_s: float) -> bool:
        """Try :meth:`sync` until the replica is confirmed current or ``timeout_s`` passes (a
        refusal ends it at once); whether it is."""
        deadline_s = time.monotonic() + timeout_s
        while True:
            try:
                self.sync()
                return True
            except ReplicaError as error:
                self.error = str(error)
                return False
            except (bus.BusError, MapDatabaseError) as error:
                self.error = str(error)
            if time.monotonic() >= deadline_s or self._stop.wait(0.2):
                return False

    def start(self) -> None:
        """Run rounds on a thread of its own: after each ``changed`` and every ``poll_s``."""
        self._thread = threading.Thread(target=self._run, name="map-replica", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        online = True
        while not self._stop.is_set():
            self._wake.wait(self.poll_s)
            self._wake.clear()
            if self._stop.is_set():
                return
            try:
                self.sync()
                if not online:
                    _log.warning("map %s reached again: replica caught up", self.map_id)
                online = True
            except (bus.BusError, MapDatabaseError) as error:
                if str(error) != self.error:
                    _log.warning("map %s: %s (localizing from the replica as it is)",
                                 self.map_id, error)  # fmt: skip
                self.error = str(error)
                online = False

    def close(self, wait_s: float = 2.0) -> None:
        """Stop the rounds and the subscription (the replica file stays)."""
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(wait_s)
        bus.undeclare_all(self._entities)
