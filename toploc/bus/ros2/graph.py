"""Graph discovery on rmw_zenoh: each ROS entity declares a liveliness token whose key says what
it is (rmw_zenoh ``docs/design.md``, "Graph Cache"; built by ``liveliness::Entity`` in
``liveliness_utils.cpp``). ``ros2 node list``, ``ros2 topic list`` and ``ros2 service call``
see what the tokens say.

A node::

    @ros2_lv/<domain>/<session zid>/<node id>/<node id>/NN/<enclave>/<namespace>/<node name>

a publisher (``MP``), subscription (``MS``), service server (``SS``) or client (``SC``)::

    @ros2_lv/<domain>/<zid>/<node id>/<entity id>/<kind>/<enclave>/<namespace>/<node name>/
        <mangled full name>/<DDS type name>/<type hash>/<QoS>

(one key; names mangled, ``/`` as ``%``; an empty enclave or namespace is ``%``). The QoS
chunk is ``qos_to_keyexpr``'s (:meth:`QoS.to_keyexpr`). Each entity's GID is the XXH3 128-bit
hash of its token's key, the low 64 bits first, as rmw_zenoh makes it (:func:`entity_gid`).
"""

from __future__ import annotations

from dataclasses import dataclass

import xxhash

from toploc.bus.ros2.keys import check_domain_id, check_namespace, check_node_name, mangle

ADMIN_SPACE = "@ros2_lv"
NODE = "NN"
PUBLISHER = "MP"
SUBSCRIPTION = "MS"
SERVICE = "SS"
CLIENT = "SC"
ENTITY_KINDS = (PUBLISHER, SUBSCRIPTION, SERVICE, CLIENT)

# rmw's enum values (rmw/types.h), as the QoS chunk writes them.
RELIABLE, BEST_EFFORT = 1, 2
TRANSIENT_LOCAL, VOLATILE = 1, 2
KEEP_LAST, KEEP_ALL = 1, 2


@dataclass(frozen=True)
class QoS:
    """The QoS of an endpoint, as far as toploc sets it (deadline, lifespan and liveliness keep
    rmw_zenoh's defaults: infinite, automatic). rmw_zenoh's defaults (``qos.cpp``): reliable,
    volatile, keep last, depth 42."""

    reliability: int = RELIABLE
    durability: int = VOLATILE
    history: int = KEEP_LAST
    depth: int = 42

    def to_keyexpr(self) -> str:
        """The QoS chunk of a liveliness token (``qos_to_keyexpr``): each field that differs
        from rmw_zenoh's default, empty where it is the default, as
        ``<reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:
        <liveliness>,<lease s>,<ns>``; e.g. a transient-local depth-1 publisher is
        ``:1:,1:,:,:,,``."""
        default = QoS()

        def part(value: int, default_value: int) -> str:
            return "" if value == default_value else str(value)

        return (
            f"{part(self.reliability, default.reliability)}:"
            f"{part(self.durability, default.durability)}:"
            f"{part(self.history, default.history)},{part(self.depth, default.depth)}:"
            ",:,:,,"
        )


LATCHED = QoS(durability=TRANSIENT_LOCAL, depth=1)
"""A latched topic, as ``/amcl_pose`` and ``/map``: reliable, transient local, depth 1."""
SERVICES_DEFAULT = QoS(depth=10)
"""rmw's ``rmw_qos_profile_services_default``: reliable, volatile, keep last 10."""


@dataclass(frozen=True)
class NodeInfo:
    """A ROS node on a Zenoh session: its domain, namespace, name and SROS enclave, the session's
    Zenoh id (``str(session.info.zid())``) and the node's id within the session."""

    domain_id: int
    namespace: str
    name: str
    zid: str
    node_id: int = 0
    enclave: str = "/"

    def __post_init__(self) -> None:
        check_domain_id(self.domain_id)
        object.__setattr__(self, "namespace", check_namespace(self.namespace))
        check_node_name(self.name)
        if not self.zid or "/" in self.zid:
            raise ValueError(f"a Zenoh session id is one key chunk, got {self.zid!r}")

    def _prefix(self, entity_id: int, kind: str) -> str:
        return (
            f"{ADMIN_SPACE}/{self.domain_id}/{self.zid}/{self.node_id}/{entity_id}/{kind}/"
            f"{mangle(self.enclave)}/{mangle(self.namespace)}/{mangle(self.name)}"
        )

    def node_token(self) -> str:
        """The node's liveliness token key (kind ``NN``, its entity id its node id)."""
        return self._prefix(self.node_id, NODE)

    def entity_token(
        self, entity_id: int, kind: str, full_name: str, dds_type: str, type_hash: str, qos: QoS
    ) -> str:
        """The liveliness token key of an endpoint of this node: ``kind`` one of
        :data:`ENTITY_KINDS`, ``full_name`` fully qualified (``/toploc/belief``), ``dds_type``
        the DDS type name (a service's without ``Request_``/``Response_``)."""
        if kind not in ENTITY_KINDS:
            raise ValueError(f"entity kind must be one of {ENTITY_KINDS}, got {kind!r}")
        if entity_id == self.node_id:
            raise ValueError(f"entity id {entity_id} is the node's own id")
        return (
            f"{self._prefix(entity_id, kind)}/{mangle(full_name)}/{mangle(dds_type)}/"
            f"{mangle(type_hash)}/{qos.to_keyexpr()}"
        )


def entity_gid(token_key: str) -> bytes:
    """The 16-byte GID of the entity whose liveliness token is ``token_key``: XXH3-128 of the
    key, its low 64 bits then its high 64 bits, each little-endian (``Entity::Entity``)."""
    digest = xxhash.xxh3_128_intdigest(token_key.encode())
    return digest.to_bytes(16, "little")
