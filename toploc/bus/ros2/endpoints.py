"""A ROS 2 node's endpoints on a Zenoh session, as rmw_zenoh declares them: :class:`RosNode`
(the ``NN`` token), its publishers (:meth:`RosNode.publisher`: a zenoh-ext advanced publisher
and an ``MP`` token) and its service servers (:meth:`RosNode.service`: a complete queryable and
an ``SS`` token). Undeclare with :meth:`RosNode.close`.

Transient local (``/amcl_pose``'s QoS, :data:`~toploc.bus.ros2.graph.LATCHED`) is what
rmw_zenoh's ``PublisherData::make`` makes of it: an ``AdvancedPublisher`` with a cache of
``depth`` samples and publisher detection, so that an rmw_zenoh transient-local subscription
(an ``AdvancedSubscriber`` with ``history.detect_late_publishers``) finds it and queries its
cache: a late joiner gets the latest sample. Reliable and transient local adds sample-miss
detection with a sporadic heartbeat every 0.5 s (rmw_zenoh's
``SAMPLE_MISS_DETECTION_HEARTBEAT_PERIOD``), from which rmw_zenoh's subscription recovers a
sample it missed.

Every sample and reply carries the :class:`~toploc.bus.ros2.attachment.Attachment`; a request
without one, or whose payload is not a CDR request of the service's type, is not handed to the
handler (:meth:`RosNode.service`).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh
import zenoh.ext

from toploc.bus.ros2.attachment import Attachment
from toploc.bus.ros2.codec import Ros2Types
from toploc.bus.ros2.graph import (
    PUBLISHER,
    RELIABLE,
    SERVICE,
    SERVICES_DEFAULT,
    TRANSIENT_LOCAL,
    NodeInfo,
    QoS,
    entity_gid,
)
from toploc.bus.ros2.keys import data_key, dds_type_name, fully_qualified_name
from toploc.bus.subscriptions import undeclare_all

HEARTBEAT_PERIOD_S = 0.5
_log = logging.getLogger(__name__)

ServiceHandler = Callable[[Any], Any]
"""A service's work: the request message in, the response message out."""
Refusal = Callable[[str], Any | None]
"""What a service answers a request it cannot take (``why`` in): a response message that says
so (e.g. Trigger's ``success=false``), or ``None`` for a Zenoh error reply."""


class RosPublisher:
    """One topic of a :class:`RosNode`: ``put(message)`` serializes it to CDR and publishes it
    with the attachment (sequence numbers from 1, as rmw_zenoh's)."""

    def __init__(
        self,
        session: zenoh.Session,
        node: NodeInfo,
        entity_id: int,
        name: str,
        type_name: str,
        types: Ros2Types,
        qos: QoS,
    ) -> None:
        self.full_name = fully_qualified_name(node.namespace, node.name, name)
        self.type_name = type_name
        self.types = types
        type_hash = types.type_hash(type_name)
        self.key = data_key(node.domain_id, self.full_name, type_name, type_hash)
        self.token_key = node.entity_token(
            entity_id, PUBLISHER, self.full_name, dds_type_name(type_name), type_hash, qos
        )
        self.gid = entity_gid(self.token_key)
        self._lock = threading.Lock()
        self._sequence = 0
        latched = qos.durability == TRANSIENT_LOCAL
        miss = None
        if latched and qos.reliability == RELIABLE:
            miss = zenoh.ext.MissDetectionConfig(
                heartbeat=None, sporadic_heartbeat=HEARTBEAT_PERIOD_S
            )
        self._publisher = zenoh.ext.declare_advanced_publisher(
            session,
            self.key,
            reliability=zenoh.Reliability.RELIABLE
            if qos.reliability == RELIABLE
            else zenoh.Reliability.BEST_EFFORT,
            congestion_control=zenoh.CongestionControl.DROP,
            cache=zenoh.ext.CacheConfig(qos.depth) if latched else None,
            publisher_detection=latched or None,
            sample_miss_detection=miss,
        )
        self._token = session.liveliness().declare_token(self.token_key)

    def put(self, message: Any) -> None:
        """Publish ``message`` (of this topic's type) with the next sequence number."""
        payload = self.types.serialize(message, self.type_name)
        with self._lock:
            self._sequence += 1
            attachment = Attachment(self._sequence, time.time_ns(), self.gid)
            self._publisher.put(payload, attachment=attachment.to_bytes())

    def undeclare(self) -> None:
        """Withdraw the token, then the publisher."""
        undeclare_all([self._token, self._publisher])


class RosService:
    """One service server of a :class:`RosNode` (see :meth:`RosNode.service`)."""

    def __init__(
        self,
        session: zenoh.Session,
        node: NodeInfo,
        entity_id: int,
        name: str,
        type_name: str,
        types: Ros2Types,
        handler: ServiceHandler,
        refuse: Refusal,
    ) -> None:
        self.full_name = fully_qualified_name(node.namespace, node.name, name)
        self.type_name = type_name
        self.types = types
        self.handler = handler
        self.refuse = refuse
        type_hash = types.type_hash(type_name)
        self.key = data_key(node.domain_id, self.full_name, type_name, type_hash)
        self.token_key = node.entity_token(
            entity_id, SERVICE, self.full_name, dds_type_name(type_name), type_hash,
            SERVICES_DEFAULT,
        )  # fmt: skip
        self._queryable = session.declare_queryable(
            self.key, zenoh.handlers.Callback(self._on_query, indirect=True), complete=True
        )
        self._token = session.liveliness().declare_token(self.token_key)

    def _response(self, payload: bytes) -> Any | None:
        """The response to the request ``payload``: the handler's, or the refusal of a payload
        that is not a request of this type, or of a handler that raised."""
        try:
            request = self.types.deserialize(payload, f"{self.type_name}_Request")
        except ValueError as error:
            _log.warning("%s: malformed request: %s", self.full_name, error)
            return self.refuse(f"malformed request: {error}")
        try:
            return self.handler(request)
        except Exception as error:  # a ROS-level failure reply, never a dropped request
            _log.warning("%s failed: %s", self.full_name, error)
            return self.refuse(f"{type(error).__name__}: {error}")

    def _on_query(self, query: zenoh.Query) -> None:
        with query:
            raw = None if query.attachment is None else query.attachment.to_bytes()
            try:
                attachment = Attachment.from_bytes(raw)
            except ValueError as error:  # no client to answer: rmw_zenoh matches by it
                _log.warning("%s: request refused: %s", self.full_name, error)
                _reply_err(query, f"{self.full_name}: {error}")
                return
            payload = b"" if query.payload is None else query.payload.to_bytes()
            response = self._response(payload)
            if response is None:
                _reply_err(query, f"{self.full_name}: the request was not served")
                return
            data = self.types.serialize(response, f"{self.type_name}_Response")
            try:
                query.reply(self.key, data, attachment=attachment.reply().to_bytes())
            except zenoh.ZError:  # the session is closing
                _log.debug("%s: could not send the reply", self.full_name)

    def undeclare(self) -> None:
        """Withdraw the token, then the queryable."""
        undeclare_all([self._token, self._queryable])


def _reply_err(query: zenoh.Query, text: str) -> None:
    try:
        query.reply_err(text)
    except zenoh.ZError:
        _log.debug("could not send the error reply: %s", text)


class RosNode:
    """A ROS 2 node ``info`` on ``session`` (an rmw_zenoh context of one node): its ``NN``
    token at once, then publishers and services, each with the next entity id."""

    def __init__(self, session: zenoh.Session, info: NodeInfo, types: Ros2Types) -> None:
        self.session = session
        self.info = info
        self.types = types
        self._next_id = info.node_id + 1
        self._endpoints: list[RosPublisher | RosService] = []
        self._token = session.liveliness().declare_token(info.node_token())

    def _entity_id(self) -> int:
        entity_id, self._next_id = self._next_id, self._next_id + 1
        return entity_id

    def publisher(self, name: str, type_name: str, qos: QoS) -> RosPublisher:
        """A publisher of ``type_name`` on ``name`` (``~/x`` private, ``x`` relative, ``/x``
        absolute)."""
        publisher = RosPublisher(
            self.session, self.info, self._entity_id(), name, type_name, self.types, qos
        )
        self._endpoints.append(publisher)
        return publisher

    def service(
        self, name: str, type_name: str, handler: ServiceHandler, refuse: Refusal
    ) -> RosService:
        """A server of service ``type_name`` on ``name``: each request with an attachment and a
        CDR payload of ``<type>_Request`` gets ``handler(request)`` as its reply, with the
        request's sequence number and client GID. A malformed payload, or a handler that raises,
        gets ``refuse(why)`` (a Zenoh error reply if that is ``None``); a request without a
        valid attachment an error reply (rmw_zenoh's own server drops it)."""
        service = RosService(
            self.session, self.info, self._entity_id(), name, type_name, self.types, handler,
            refuse,
        )  # fmt: skip
        self._endpoints.append(service)
        return service

    def close(self) -> None:
        """Undeclare the endpoints, then the node's token (the session stays open)."""
        for endpoint in reversed(self._endpoints):
            endpoint.undeclare()
        self._endpoints.clear()
        undeclare_all([self._token])
