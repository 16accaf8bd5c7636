"""The localizer's client: :class:`LocalizerClient` queries and follows a
:class:`~toploc.nodes.localizer.LocalizerNode` (``localizer/belief``, ``localizer/localize``,
``localizer/reset``); every belief it returns is checked by
:func:`~toploc.bus.messages.check_belief`."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import zenoh

from toploc import bus
from toploc.bus.clients.base import Client
from toploc.bus.messages import check_belief
from toploc.bus.schemas import BELIEF, LOCALIZE, RESET

LOCALIZE_TIMEOUT_S = 300.0
"""How long :meth:`LocalizerClient.localize` waits: an active localization drives the robot."""


class LocalizerClient(Client):
    """Query and follow the :class:`~toploc.nodes.localizer.LocalizerNode` of robot ``robot_id``
    over ``session``.

    Every call raises :class:`~toploc.bus.BusTimeout` if no node answers in time,
    :class:`~toploc.bus.BusReplyError` with the node's message if the service failed.
    """

    def __init__(
        self,
        session: zenoh.Session,
        robot_id: str,
        timeout_s: float = bus.DEFAULT_TIMEOUT_S,
        localize_timeout_s: float = LOCALIZE_TIMEOUT_S,
    ) -> None:
        super().__init__(session, robot_id, timeout_s)
        self.localize_timeout_s = localize_timeout_s

    def _query(self, suffix: str, payload: bytes | None, timeout_s: float) -> dict[str, Any]:
        key_expr = self.key(suffix)
        message = bus.request_json(self.session, key_expr, BELIEF.fields, payload, timeout_s)
        return check_belief(key_expr, message)

    def belief(self) -> dict[str, Any]:
        """The node's latest belief."""
        return self._query(bus.LOCALIZER_BELIEF, None, self.timeout_s)

    def localize(self, active: bool = False) -> dict[str, Any]:
        """Localize now (moving to disambiguate if ``active``); waits up to
        ``localize_timeout_s`` for the new belief."""
        payload = LOCALIZE.encode({"active": active, "timeout_s": self.localize_timeout_s})
        return self._query(bus.LOCALIZER_LOCALIZE, payload, self.localize_timeout_s)

    def reset(self, prior: Mapping[str, float] | None = None) -> dict[str, Any]:
        """Reset to a uniform belief, or to ``prior`` ({room: p})."""
        payload = RESET.encode({} if prior is None else {"prior": dict(prior)})
        return self._query(bus.LOCALIZER_RESET, payload, self.timeout_s)

    def subscribe(self, callback: Callable[[dict[str, Any]], None]) -> zenoh.Subscriber:
        """Call ``callback(belief)`` for each published belief (on a zenoh thread); malformed
        publications are skipped. Undeclare the returned subscriber, or :meth:`close`."""
        return self._subscribe(
            bus.LOCALIZER_BELIEF,
            lambda key_expr, data: check_belief(key_expr, BELIEF.decode(key_expr, data, False)),
            callback,
        )
