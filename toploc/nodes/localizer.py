"""The localizer on the Zenoh bus: :class:`LocalizerNode` serves a :class:`LocalizationService`,
:class:`~toploc.bus.clients.localizer.LocalizerClient` (also importable from here) is what an
application uses to talk to it.

Keys under ``toploc/<robot_id>/``:

- ``localizer/belief``: queryable (the latest belief) and publication (whenever it changes).
- ``localizer/localize`` (queryable): optional ``{"kind": "localize", "active": bool,
  "timeout_s": float}`` (default: not active, no timeout); localize now, reply the new belief.
  ``active`` allows the robot to move to disambiguate, so the reply can take minutes: the
  client's timeout must allow for it. ``timeout_s`` is how long the client waits: a query still
  waiting for its turn after that is dropped unrun.
- ``localizer/reset`` (queryable): optional ``{"kind": "reset", "prior": {room: p}}``; uniform
  belief without.
- liveliness token ``alive/localizer``.

The belief is the one JSON form of :meth:`localizer.belief.RoomBelief.to_json` (``kind:
"belief"``); every belief sent or received is checked by :meth:`RoomBelief.from_json`.

A robot gone: the node follows the robot node's liveliness token (``alive/robot``). Once it has
seen the robot and the token goes (the robot node stopped, crashed or lost its link), every
belief it answers or publishes carries ``"stale": true`` and ``"age_s"`` (seconds since the
belief's ``stamp``; the last belief is still served, nothing updates it), and the stale belief
is published at once; when the token comes back a fresh (unmarked) belief is published. Both
fields are optional: :func:`~toploc.bus.messages.check_belief` keeps them, and a reader that does
not know them (``RoomBelief.from_json``) ignores them. A localizer on a replica of a site map
(``map_age`` given) adds ``"map_age_s"`` to each belief in the same way: seconds since the
replica last confirmed it was the map's current version (null: never).

Threading: each queryable runs its handler on a Python thread of its own (zenoh-python's
indirect callbacks), so a long ``localize(active=True)`` does not delay ``belief`` or
``reset`` queries; each ``localize`` query gets a thread of its own as it arrives, and the
service runs them one after another (dropping those whose client has given up). The service
must therefore tolerate ``belief()``/``reset()`` being called while ``localize()`` runs. A
service exception becomes an error reply with its message; the node stays up.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any, Protocol

import zenoh

from toploc import bus
from toploc.bus.clients.localizer import LOCALIZE_TIMEOUT_S, LocalizerClient
from toploc.bus.messages import check_belief, check_prior, mark_stale
from toploc.bus.schemas import LOCALIZE, RESET
from toploc.limits import Limits
from toploc.nodes.node import Node
from toploc.runner import NoPlacesYetError

__all__ = [
    "LOCALIZE_TIMEOUT_S",
    "NODE_NAME",
    "ROBOT_NODE",
    "LocalizationService",
    "LocalizerClient",
    "LocalizerNode",
]

NODE_NAME = "localizer"
_log = logging.getLogger(__name__)
ROBOT_NODE = "robot"


class LocalizationService(Protocol):
    """What :class:`LocalizerNode` serves (the integrator's localization loop)."""

    def belief(self) -> dict:
        """The current belief as JSON-able dict (see the module docstring)."""
        ...

    def localize(self, active: bool, deadline_s: float | None = None) -> dict:
        """Capture, match and update now (moving to disambiguate if ``active``); the belief.
        Not started once ``deadline_s`` (``time.monotonic()``) has passed."""
        ...

    def reset(self, prior: Mapping[str, float] | None) -> dict:
        """Uniform belief over the rooms (``prior`` None) or the given prior; the belief."""
        ...


class LocalizerNode(Node):
    """Serve ``service`` on the bus under ``toploc/<robot_id>/`` within ``limits``; ``close()``
    (or ``with``)."""

    def __init__(
        self,
        session: zenoh.Session,
        robot_id: str,
        service: LocalizationService,
        limits: Limits | None = None,
        map_age: Callable[[], float | None] | None = None,
    ) -> None:
        super().__init__(session, robot_id, NODE_NAME)
        self.service = service
        self.map_age = map_age
        self.limits = limits or Limits()
        self._publish_lock = threading.Lock()
        self._last_published: dict[str, Any] | None = None
        self._robot_lock = threading.Lock()
        self._robot_seen = False
        self._robot_gone = False
        self._publisher = session.declare_publisher(self.key(bus.LOCALIZER_BELIEF))
        self.entities += [
            session.liveliness().declare_subscriber(
                bus.alive_key(robot_id, ROBOT_NODE),
                zenoh.handlers.Callback(self._on_robot_token),
                history=True,
            ),
            bus.serve(session, self.key(bus.LOCALIZER_BELIEF), self._on_belief),
            bus.serve(session, self.key(bus.LOCALIZER_LOCALIZE), self._on_localize, threaded=True),
            bus.serve(session, self.key(bus.LOCALIZER_RESET), self._on_reset),
            self._publisher,
            session.liveliness().declare_token(bus.alive_key(robot_id, NODE_NAME)),
        ]

    @property
    def robot_gone(self) -> bool:
        """Whether the robot node's token went after it was seen (the belief is stale)."""
        with self._robot_lock:
            return self._robot_gone

    def _on_robot_token(self, sample: zenoh.Sample) -> None:
        """The robot node's liveliness token came (PUT) or went (DELETE)."""
        gone = sample.kind == zenoh.SampleKind.DELETE
        with self._robot_lock:
            self._robot_seen = self._robot_seen or not gone
            was_gone, self._robot_gone = self._robot_gone, gone and self._robot_seen
            changed = was_gone != self._robot_gone
        if not changed:
            return
        _log.warning("robot node %s", "gone: the belief is stale" if gone else "back")
        try:
            self.publish(self.service.belief())
        except (bus.BusError, zenoh.ZError, NoPlacesYetError) as error:
            _log.warning("could not publish the belief: %s", error)

    def _marked(self, belief: Mapping[str, Any]) -> dict[str, Any]:
        marked = mark_stale(belief) if self.robot_gone else dict(belief)
        if self.map_age is not None:
            age_s = self.map_age()
            marked["map_age_s"] = None if age_s is None else round(age_s, 3)
        return marked

    def publish(self, belief: Mapping[str, Any]) -> bool:
        """Publish ``belief`` on ``localizer/belief`` unless it equals the last one published.

        The service calls this whenever its belief changes (e.g. during active localization);
        the node also calls it with the result of ``localize`` and ``reset``, and when the robot
        node goes or comes back. Marked stale while the robot is gone. Returns whether it was
        published. Raises BusMessageError for a belief that breaks the contract.
        """
        checked = check_belief(f"{self.key(bus.LOCALIZER_BELIEF)} (publish)", self._marked(belief))
        with self._publish_lock:
            if checked == self._last_published:
                return False
            self._publisher.put(bus.encode_message(checked))
            self._last_published = checked
        return True

    def _belief_reply(self, belief: Mapping[str, Any], publish: bool) -> bus.Reply:
        where = f"{self.key(bus.LOCALIZER_BELIEF)}: the service returned a bad belief"
        checked = check_belief(where, belief)
        if publish:  # the belief itself: how the localization that made it went is the reply's
            self.publish({k: v for k, v in checked.items() if k != "active"})
        return bus.Reply(bus.encode_message(check_belief(where, self._marked(checked))))

    def _on_belief(self, _payload: bytes | None) -> bus.Reply:
        return self._belief_reply(self.service.belief(), publish=False)

    def _decode_request(self, suffix: str, payload: bytes, kind: str) -> dict[str, Any]:
        limits = self.limits
        where = self.key(suffix)
        return bus.decode(
            where, payload, None, kind, limits.max_request_bytes, limits.max_string_chars
        )

    def _on_localize(self, payload: bytes | None) -> bus.Reply:
        received_s = time.monotonic()
        active, deadline_s = False, None
        if payload:
            where = self.key(bus.LOCALIZER_LOCALIZE)
            request = self._decode_request(bus.LOCALIZER_LOCALIZE, payload, LOCALIZE.kind)
            LOCALIZE.check_optional(where, request)
            active = request.get("active", False)
            if "timeout_s" in request:
                deadline_s = received_s + request["timeout_s"]
        _log.debug("localize request: active %s, deadline in %s s", active,
                   None if deadline_s is None else round(deadline_s - received_s, 1))  # fmt: skip
        return self._belief_reply(self.service.localize(active, deadline_s), publish=True)

    def _on_reset(self, payload: bytes | None) -> bus.Reply:
        prior = None
        if payload:
            where = self.key(bus.LOCALIZER_RESET)
            prior = check_prior(
                where, self._decode_request(bus.LOCALIZER_RESET, payload, RESET.kind).get("prior")
            )
        return self._belief_reply(self.service.reset(prior), publish=True)
