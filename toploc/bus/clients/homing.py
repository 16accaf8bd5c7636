"""The homing node's client: :class:`HomingClient` sends goals to, cancels and follows a
:class:`~toploc.nodes.homing.HomingNode` (``homing/goal``, ``homing/cancel``,
``homing/progress``)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import zenoh

from toploc import bus
from toploc.bus.clients.base import Client
from toploc.bus.schemas import CANCEL, CANCELLED, GOAL, HOMING_RESULT, PROGRESS

GOAL_TIMEOUT_S = 600.0
"""How long a goal may drive before the node gives up (reason ``timeout``)."""


class HomingClient(Client):
    """Send goals to, cancel and follow the :class:`~toploc.nodes.homing.HomingNode` of robot
    ``robot_id``."""

    def goal(self, place_id: int, timeout_s: float = GOAL_TIMEOUT_S) -> dict[str, Any]:
        """Drive to ``place_id``; the node gives up after ``timeout_s`` (reason ``timeout``),
        this call waits a little longer for its reply."""
        payload = GOAL.encode({"place_id": place_id, "timeout_s": timeout_s})
        return bus.request_json(
            self.session,
            self.key(bus.HOMING_GOAL),
            HOMING_RESULT.fields,
            payload,
            timeout_s + self.timeout_s,
        )

    def cancel(self) -> bool:
        """Cancel the running drive; whether one was running."""
        reply = bus.request_json(
            self.session,
            self.key(bus.HOMING_CANCEL),
            CANCELLED.fields,
            CANCEL.encode({}),
            self.timeout_s,
        )
        return bool(reply["cancelled"])

    def subscribe(self, callback: Callable[[dict[str, Any]], None]) -> zenoh.Subscriber:
        """Call ``callback(progress)`` for each ``homing/progress`` message (on a zenoh
        thread); malformed ones are skipped. :meth:`close` undeclares."""
        return self._subscribe(
            bus.HOMING_PROGRESS,
            lambda key_expr, data: PROGRESS.decode(key_expr, data, check_kind=False),
            callback,
        )
