"""The ROS 2 bridge: toploc's belief and services on a ROS 2 graph over rmw_zenoh, without a ROS
installation (:class:`Ros2Bridge`; the conventions are in :mod:`toploc.bus.ros2`).

It is a client of the service's own bus (``toploc/<robot_id>/localizer/*``, ``map/places``)
and a ROS 2 node named ``toploc`` on a second session, a peer of the robot's Zenoh router
(``rmw_zenohd``), in the ROS domain and namespace it is given. Names (namespace ``/``)::

    /toploc/belief_json     std_msgs/msg/String               the belief's JSON
    /diagnostics            diagnostic_msgs/msg/DiagnosticArray  state, top room, p, entropy
    /toploc/belief          toploc_msgs/msg/RoomBelief        the typed belief
    /toploc/pose            geometry_msgs/msg/PoseWithCovarianceStamped  the best place's pose
    /toploc/localize        std_srvs/srv/Trigger   localize once; message: state and room
    /toploc/localize_active std_srvs/srv/Trigger   localize, driving to disambiguate; message:
                                                   also drives, metres and why it ended
    /toploc/reinitialize_global_localization  std_srvs/srv/Empty   a uniform belief

Every topic is reliable, transient local, depth 1 (a late joiner gets the latest belief, as
``/amcl_pose``), published on every change of the belief. The pose is published when the
best place has a stored position (frame id: its room).

Following the service: each belief the localizer publishes is mirrored; when the localizer's
liveliness token (``alive/localizer``) goes, the last belief is published again marked stale
(``stale: true`` in the JSON and in RoomBelief, diagnostics level STALE) and the Trigger
services answer ``success=false``; when it comes back its belief is fetched and published.
A ROS router that goes away and comes back is rejoined by Zenoh itself (the peer keeps
reconnecting to its connect endpoints, and its tokens and publishers are declared to the new
router), with nothing for the bridge to redo.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Self

import zenoh

from toploc import bus
from toploc.bus.clients.localizer import LOCALIZE_TIMEOUT_S, LocalizerClient
from toploc.bus.clients.mapdb import MapClient, subscribe_changes
from toploc.bus.messages import mark_stale
from toploc.bus.ros2.codec import (
    DIAGNOSTIC_ARRAY,
    EMPTY,
    POSE_WITH_COVARIANCE_STAMPED,
    ROOM_BELIEF,
    STRING,
    TRIGGER,
    Ros2Types,
)
from toploc.bus.ros2.endpoints import RosNode
from toploc.bus.ros2.graph import LATCHED, NodeInfo
from toploc.bus.ros2.keys import check_domain_id, check_namespace
from toploc.bus.ros2.messages import (
    belief_diagnostics,
    belief_string,
    place_pose,
    room_belief,
    summary,
)
from toploc.runner import describe_active

NODE_NAME = "toploc"
LOCALIZER_NODE = "localizer"
BELIEF_JSON_TOPIC = "~/belief_json"
DIAGNOSTICS_TOPIC = "diagnostics"
BELIEF_TOPIC = "~/belief"
POSE_TOPIC = "~/pose"
LOCALIZE_SERVICE = "~/localize"
LOCALIZE_ACTIVE_SERVICE = "~/localize_active"
REINITIALIZE_SERVICE = "~/reinitialize_global_localization"
TOKEN_QUERY_TIMEOUT_S = 1.0  # the wait for the localizer's token when the bridge has not heard it
_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Ros2Settings:
    """Where on the ROS graph: the ``ROS_DOMAIN_ID`` (0 to 232) and the node's namespace."""

    domain_id: int = 0
    namespace: str = "/"

    def __post_init__(self) -> None:
        check_domain_id(self.domain_id)
        object.__setattr__(self, "namespace", check_namespace(self.namespace))


class Ros2Bridge:
    """Mirror robot ``robot_id``'s localizer (over ``toploc_session``) onto the ROS graph of
    ``ros_session`` as node ``toploc`` (see the module docstring); ``close()`` (or ``with``)
    undeclares both sides (the sessions stay open)."""

    def __init__(
        self,
        toploc_session: zenoh.Session,
        robot_id: str,
        ros_session: zenoh.Session,
        settings: Ros2Settings | None = None,
        timeout_s: float = bus.DEFAULT_TIMEOUT_S,
        localize_timeout_s: float = LOCALIZE_TIMEOUT_S,
    ) -> None:
        self.robot_id = bus.check_robot_id(robot_id)
        self.settings = settings or Ros2Settings()
        self.types = Ros2Types()
        self._toploc_session = toploc_session
        self.localizer = LocalizerClient(toploc_session, robot_id, timeout_s, localize_timeout_s)
        self.map = MapClient(toploc_session, robot_id, timeout_s)
        self._lock = threading.Lock()
        self._publish_lock = threading.Lock()  # one belief's messages before the next's
        self._belief: dict[str, Any] | None = None
        self._published: dict[str, Any] | None = None
        self._publications_in = 0  # beliefs the localizer published that reached this bridge
        self._localizer_up = False
        self._places: dict[int, dict[str, Any]] = {}
        info = NodeInfo(
            self.settings.domain_id, self.settings.namespace, NODE_NAME,
            str(ros_session.info.zid()),
        )  # fmt: skip
        self.node = RosNode(ros_session, info, self.types)
        self.belief_json = self.node.publisher(BELIEF_JSON_TOPIC, STRING, LATCHED)
        self.diagnostics = self.node.publisher(DIAGNOSTICS_TOPIC, DIAGNOSTIC_ARRAY, LATCHED)
        self.belief = self.node.publisher(BELIEF_TOPIC, ROOM_BELIEF, LATCHED)
        self.pose = self.node.publisher(POSE_TOPIC, POSE_WITH_COVARIANCE_STAMPED, LATCHED)
        self.node.service(LOCALIZE_SERVICE, TRIGGER, lambda _: self._localize(False), self._fail)
        self.node.service(
            LOCALIZE_ACTIVE_SERVICE, TRIGGER, lambda _: self._localize(True), self._fail
        )
        self.node.service(REINITIALIZE_SERVICE, EMPTY, self._reinitialize, lambda _why: None)
        self._toploc_entities: list[Any] = [
            subscribe_changes(toploc_session, robot_id, self._forget_places),
            toploc_session.liveliness().declare_subscriber(
                bus.alive_key(robot_id, LOCALIZER_NODE),
                zenoh.handlers.Callback(self._on_localizer_token),
                history=True,
            ),
        ]
        self.localizer.subscribe(self._on_published)

    # --- the toploc side ---------------------------------------------------------------------

    @property
    def localizer_up(self) -> bool:
        """Whether the localizer's liveliness token is on toploc's bus."""
        with self._lock:
            return self._localizer_up

    @property
    def last_published(self) -> dict[str, Any] | None:
        """The belief the topics carry now (``None`` before the first)."""
        with self._lock:
            return self._published

    def _on_localizer_token(self, sample: zenoh.Sample) -> None:
        up = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            self._localizer_up = up
            last = self._belief
        if not up:
            _log.warning("toploc's localizer left the bus: the ROS topics carry a stale belief")
            if last is not None:
                self.publish(mark_stale(last))
            return
        with self._lock:
            publications_before = self._publications_in
        try:
            answer = self.localizer.belief()
        except bus.BusError as error:
            _log.warning("could not fetch the localizer's belief: %s", error)
            return
        self._publish(answer, unless_published_since=publications_before)

    def _forget_places(self) -> None:
        with self._lock:
            self._places.clear()

    def _place(self, place_id: int) -> dict[str, Any] | None:
        """The map's place ``place_id`` (the map node's ``map/places``, cached until
        ``map/changed``); ``None`` if the map node does not answer or has no such place."""
        with self._lock:
            place = self._places.get(place_id)
        if place is not None:
            return place
        try:
            places = {int(p["id"]): p for p in self.map.places() if "id" in p}
        except bus.BusError as error:
            _log.info("no pose for place %d: %s", place_id, error)
            return None
        with self._lock:
            self._places = places
        return places.get(place_id)

    def _on_published(self, belief: dict[str, Any]) -> None:
        with self._lock:
            self._publications_in += 1
        self.publish(belief)

    # --- the ROS side ------------------------------------------------------------------------

    def publish(self, belief: Mapping[str, Any]) -> bool:
        """Publish ``belief`` on every topic unless it equals the last one published; whether
        it was. Called with each belief the localizer publishes or answers; marked stale while
        the localizer's token is gone."""
        return self._publish(belief)

    def _publish(
        self, belief: Mapping[str, Any], unless_published_since: int | None = None
    ) -> bool:
        """:meth:`publish`, but with ``unless_published_since`` (the count of the localizer's
        publications when ``belief`` was asked for) drop ``belief`` if one came since: the answer
        was on its way while a newer belief was published, and putting it then would leave the
        topics, and their late joiners, on the older belief."""
        current = dict(belief)
        with self._publish_lock:
            with self._lock:
                if unless_published_since not in (None, self._publications_in):
                    _log.info(
                        "the localizer published a belief while its answer was on the way: "
                        "the answer, older, is not published"
                    )
                    return False
                if not current.get("stale"):
                    self._belief = current
                    if not self._localizer_up:  # a publication that came after its token went
                        current = mark_stale(current)
                if current == self._published:
                    return False
                self._published = current
            if not self._put(current):
                with self._lock:
                    self._published = None  # the next belief, even an equal one, tries again
        return True

    def _put(self, current: dict[str, Any]) -> bool:
        """Put ``current`` on every topic; whether every put went out. A topic whose put
        fails (the session closing) is logged and does not keep the others from theirs."""
        types = self.types
        messages = [
            (self.belief_json, belief_string(types, current)),
            (self.diagnostics, belief_diagnostics(types, current, self.robot_id)),
            (self.belief, room_belief(types, current)),
        ]
        best = current.get("best_place") or {}
        if best.get("place_id") is not None:
            place = self._place(int(best["place_id"]))
            pose = None if place is None else place_pose(types, current, place)
            if pose is not None:
                messages.append((self.pose, pose))
        sent = True
        for publisher, message in messages:
            try:
                publisher.put(message)
            except zenoh.ZError as error:
                _log.warning("could not publish on %s: %s", publisher.full_name, error)
                sent = False
        return sent

    def _trigger(self, success: bool, message: str) -> Any:
        return self.types.message(f"{TRIGGER}_Response", success=success, message=message)

    def _fail(self, why: str) -> Any:
        return self._trigger(False, why)

    def _localizer_on_bus(self) -> bool:
        """Whether the localizer's token is on toploc's bus: as this bridge last heard, or, when
        it has not heard it (yet), as a liveliness query finds now. A call that comes just after
        ``toploc serve --ros2`` started can come before the token's history reached this bridge;
        it is served, not told that the localizer is away."""
        if self.localizer_up:
            return True
        key = bus.alive_key(self.robot_id, LOCALIZER_NODE)
        try:
            return bus.token_present(self._toploc_session, key, TOKEN_QUERY_TIMEOUT_S)
        except bus.BusError as error:
            _log.warning("could not ask toploc's bus for the localizer's token: %s", error)
            return False

    def _localize(self, active: bool) -> Any:
        if not self._localizer_on_bus():
            return self._fail(
                f"toploc's localizer for robot {self.robot_id!r} is not on the bus "
                f"({bus.alive_key(self.robot_id, LOCALIZER_NODE)}): is toploc serve running?"
            )
        try:
            reply = self.localizer.localize(active)
        except bus.BusError as error:
            return self._fail(str(error))
        how = reply.get("active")  # how an active localization went: the reply's, not a topic's
        belief = {k: v for k, v in reply.items() if k != "active"}
        self.publish(belief)
        went = "" if how is None else f"; {describe_active(how)}"
        return self._trigger(True, summary(belief) + went)

    def _reinitialize(self, _request: Any) -> Any:
        self.publish(self.localizer.reset())  # a failure is a Zenoh error reply (Empty says none)
        return self.types.message(f"{EMPTY}_Response", structure_needs_at_least_one_member=0)

    def close(self) -> None:
        """Stop following toploc's bus, then leave the ROS graph (in this order, so that no
        belief arrives to be put on a publisher already undeclared)."""
        self.localizer.close()
        bus.undeclare_all(self._toploc_entities)
        self.node.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
