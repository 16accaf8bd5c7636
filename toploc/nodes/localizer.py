"""The localizer on the Zenoh bus: :class:`LocalizerNode` serves a :class:`LocalizationService`,
:class:`LocalizerClient` is what an application uses to talk to it.

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
fields are optional: :func:`check_belief` keeps them, and a reader that does not know them
(``RoomBelief.from_json``) ignores them.

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

from localizer.belief import RoomBelief
from toploc import bus
from toploc.limits import Limits
from toploc.nodes.node import Client, Node
from toploc.runner import NoPlacesYetError

NODE_NAME = "localizer"
_log = logging.getLogger(__name__)
LOCALIZE_TIMEOUT_S = 300.0
ROBOT_NODE = "robot"
STALE_FIELDS: dict[str, bus.FieldType] = {"stale": bool, "age_s": (float, type(None))}


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


def check_belief(where: str, belief: Mapping[str, Any]) -> dict[str, Any]:
    """The belief message (``RoomBelief.to_json()``) ``belief`` stands for, checked field by
    field, with the optional ``stale`` (bool) and ``age_s`` (a number >= 0, or null) kept;
    :class:`~toploc.bus.BusMessageError` prefixed ``where`` naming the bad field."""
    try:
        checked = RoomBelief.from_json(belief).to_json()
    except ValueError as error:
        raise bus.BusMessageError(f"{where}: {error}") from None
    optional = {k: t for k, t in STALE_FIELDS.items() if k in belief}
    bus.check_fields(where, belief, optional)
    if belief.get("age_s") is not None and belief["age_s"] < 0:
        raise bus.BusMessageError(f"{where}: field 'age_s' must be >= 0, got {belief['age_s']!r}")
    return {**checked, **{k: belief[k] for k in optional}}


def mark_stale(belief: Mapping[str, Any], now_s: float | None = None) -> dict[str, Any]:
    """``belief`` with ``"stale": true`` and ``"age_s"``: seconds since its ``stamp`` (``now_s``,
    default ``time.time()``), null without a stamp."""
    stamp = belief.get("stamp")
    now = time.time() if now_s is None else now_s
    age_s = None if stamp is None else max(0.0, now - stamp)
    return {**belief, "stale": True, "age_s": age_s}


def check_prior(where: str, prior: Any) -> dict[str, float] | None:
    """``None`` or a ``{room: weight}`` dict of finite non-negative numbers; else raise."""
    if prior is None:
        return None
    if not isinstance(prior, dict) or not prior:
        raise bus.BusMessageError(
            f"{where}: prior must be a non-empty object {{room: p}}, got {prior!r}"
        )
    for room, p in prior.items():
        if not bus.has_type(p, float) or p < 0:
            raise bus.BusMessageError(f"{where}: prior[{room!r}] must be a number >= 0, got {p!r}")
    return {room: float(p) for room, p in prior.items()}


class LocalizerNode(Node):
    """Serve ``service`` on the bus under ``toploc/<robot_id>/`` within ``limits``; ``close()``
    (or ``with``)."""

    def __init__(
        self,
        session: zenoh.Session,
        robot_id: str,
        service: LocalizationService,
        limits: Limits | None = None,
    ) -> None:
        super().__init__(session, robot_id, NODE_NAME)
        self.service = service
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
        return mark_stale(belief) if self.robot_gone else dict(belief)

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
        if publish:
            self.publish(checked)
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
            request = self._decode_request(bus.LOCALIZER_LOCALIZE, payload, "localize")
            optional = {"active": bool, "timeout_s": float}
            bus.check_fields(where, request, {k: t for k, t in optional.items() if k in request})
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
                where, self._decode_request(bus.LOCALIZER_RESET, payload, "reset").get("prior")
            )
        return self._belief_reply(self.service.reset(prior), publish=True)


class LocalizerClient(Client):
    """Query and follow a :class:`LocalizerNode` of robot ``robot_id`` over ``session``.

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
        message = bus.request_json(self.session, key_expr, {}, payload, timeout_s)
        return check_belief(key_expr, message)

    def belief(self) -> dict[str, Any]:
        """The node's latest belief."""
        return self._query(bus.LOCALIZER_BELIEF, None, self.timeout_s)

    def localize(self, active: bool = False) -> dict[str, Any]:
        """Localize now (moving to disambiguate if ``active``); waits up to
        ``localize_timeout_s`` for the new belief."""
        payload = bus.encode("localize", {"active": active, "timeout_s": self.localize_timeout_s})
        return self._query(bus.LOCALIZER_LOCALIZE, payload, self.localize_timeout_s)

    def reset(self, prior: Mapping[str, float] | None = None) -> dict[str, Any]:
        """Reset to a uniform belief, or to ``prior`` ({room: p})."""
        payload = bus.encode("reset", {} if prior is None else {"prior": dict(prior)})
        return self._query(bus.LOCALIZER_RESET, payload, self.timeout_s)

    def subscribe(self, callback: Callable[[dict[str, Any]], None]) -> zenoh.Subscriber:
        """Call ``callback(belief)`` for each published belief (on a zenoh thread); malformed
        publications are skipped. Undeclare the returned subscriber, or :meth:`close`."""
        return self._subscribe(
            bus.LOCALIZER_BELIEF,
            lambda key_expr, data: check_belief(key_expr, bus.decode(key_expr, data)),
            callback,
        )
