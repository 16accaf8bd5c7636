"""The localization service: one localizer, one robot, a belief that clients can ask for.

:class:`LocalizationRunner` is what :class:`toploc.nodes.localizer.LocalizerNode` serves on the bus
(it knows nothing of Zenoh). Zenoh answers each query on its own thread, so the runner is
thread-safe: one localization at a time (a second waits), ``belief()`` always answers at once
with the latest snapshot, and ``reset()`` during a run is refused with a clear error rather
than changing the belief under the running loop.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from typing import Any

from localizer.active import ActiveParams, localize_actively
from localizer.belief import RoomBelief
from localizer.localizer import Localizer
from localizer.robot_protocol import Robot

RESET_WAIT_S = 1.0


class LocalizationRunner:
    """Localize ``robot`` against ``localizer``'s map on request; publish every new belief.

    ``publish`` is called with each belief message (e.g. ``LocalizerNode.publish``); it may be
    set after construction, since the node needs the runner first.
    """

    def __init__(
        self,
        localizer: Localizer,
        robot: Robot,
        policy: str = "separating",
        params: ActiveParams | None = None,
        publish: Callable[[dict[str, Any]], object] | None = None,
    ) -> None:
        self.localizer = localizer
        self.robot = robot
        self.policy = policy
        self.params = params or ActiveParams()
        self.publish = publish
        self._run_lock = threading.Lock()
        self._snapshot_lock = threading.Lock()
        self._latest = localizer.belief().to_json()

    def _set(self, belief: RoomBelief) -> None:
        message = belief.to_json()
        with self._snapshot_lock:
            self._latest = message
        if self.publish is not None:
            self.publish(message)

    def belief(self) -> dict[str, Any]:
        """The latest belief (answers at once, also while a localization runs)."""
        with self._snapshot_lock:
            return dict(self._latest)

    def localize(self, active: bool) -> dict[str, Any]:
        """Capture and update the belief; with ``active``, start from a uniform belief and drive
        to disambiguate while it is ambiguous (this takes a while)."""
        with self._run_lock:
            if active:
                result = localize_actively(
                    self.localizer, self.robot, self.policy, self.params, on_belief=self._set
                )
                belief = result.final
            else:
                observation = self.localizer.observe(self.robot.capture().image)
                belief = self.localizer.update(observation)
            self._set(belief)
            return self.belief()

    def reset(self, prior: Mapping[str, float] | None) -> dict[str, Any]:
        """Uniform belief, or ``prior``; ``RuntimeError`` while a localization is running."""
        if not self._run_lock.acquire(timeout=RESET_WAIT_S):
            raise RuntimeError("a localization is running; reset when it has finished")
        try:
            self._set(self.localizer.reset(prior))
        finally:
            self._run_lock.release()
        return self.belief()
