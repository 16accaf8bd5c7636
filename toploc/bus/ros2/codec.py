"""ROS 2 types, CDR and type hashes, from ``rosbags`` (its type store of ROS 2 Jazzy), with the
types toploc serves added: std_srvs's ``Trigger`` and ``Empty`` and ``toploc_msgs``'s
``RoomBelief`` (:class:`Ros2Types`).

Type hashes are RIHS01 (REP-2016): the SHA-256 of the type description's JSON, as rosidl's
``rosidl_generator_type_description`` makes it and rmw_zenoh puts in keys and tokens. rosbags
makes them (``Typestore.hash_rihs01``) with one difference from rosidl: rosidl reads a ``.msg``
``char`` as ``uint8`` (``rosidl_adapter`` maps it so before the type description is made),
rosbags keeps it as a type of its own (type id 13). ``service_msgs/msg/ServiceEventInfo`` holds
a ``char[16]``, and every service type's description holds it (through its ``_Event`` type), so
:meth:`Ros2Types.type_hash` hashes a copy of the definitions with ``char`` read as ``uint8``.

A service ``pkg/srv/Name`` is described as rosidl describes it: fields ``request_message``
(``Name_Request``), ``response_message`` (``Name_Response``) and ``event_message``
(``Name_Event``: ``info`` a ``service_msgs/msg/ServiceEventInfo``, ``request`` and ``response``
sequences of at most one); an empty request or response has rosidl's one ``uint8
structure_needs_at_least_one_member``, which CDR carries too (one byte).
"""

from __future__ import annotations

from importlib import resources
from typing import Any

from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import Nodetype
from rosbags.typesys.store import Typestore

STRING = "std_msgs/msg/String"
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"
POSE_WITH_COVARIANCE_STAMPED = "geometry_msgs/msg/PoseWithCovarianceStamped"
ROOM_BELIEF = "toploc_msgs/msg/RoomBelief"
TRIGGER = "std_srvs/srv/Trigger"
EMPTY = "std_srvs/srv/Empty"
EMPTY_MEMBER = "uint8 structure_needs_at_least_one_member"
"""The one field rosidl gives an empty structure (an empty request or response)."""

SERVICES = {
    TRIGGER: ("", "bool success   # indicate successful run of triggered service\n"
                  "string message # informational, e.g. for error messages"),
    EMPTY: ("", ""),
}  # fmt: skip
"""The request and response definitions of the services toploc serves: std_srvs's
``srv/Trigger.srv`` and ``srv/Empty.srv`` (ros2/common_interfaces), each side of ``---``."""


def room_belief_definition() -> str:
    """The text of ``toploc_msgs/msg/RoomBelief.msg``: the package-data file that the
    ``toploc_msgs`` colcon package builds, so ROS and toploc read one definition."""
    package = resources.files("toploc.bus.ros2")
    return package.joinpath("toploc_msgs", "msg", "RoomBelief.msg").read_text(encoding="utf-8")


def _msg_fields(text: str, type_name: str) -> Any:
    """The rosbags field definitions of ``.msg`` ``text`` for ``type_name`` (``pkg/msg/X`` or
    ``pkg/srv/X_Request``; an empty text is rosidl's one-member structure)."""
    package, _kind, name = type_name.split("/")
    parsed = get_types_from_msg(text.strip() or EMPTY_MEMBER, f"{package}/msg/{name}")
    return parsed[f"{package}/msg/{name}"]


def service_definitions(type_name: str, request: str, response: str) -> dict[str, Any]:
    """The rosbags definitions of service ``type_name`` (``pkg/srv/Name``) whose request and
    response ``.srv`` halves are ``request`` and ``response``: ``Name_Request``,
    ``Name_Response``, ``Name_Event`` and ``Name`` itself, as rosidl describes a service."""
    req, resp, event = (f"{type_name}_{part}" for part in ("Request", "Response", "Event"))
    return {
        req: _msg_fields(request, req),
        resp: _msg_fields(response, resp),
        event: ([], [
            ("info", (Nodetype.NAME, "service_msgs/msg/ServiceEventInfo")),
            ("request", (Nodetype.SEQUENCE, ((Nodetype.NAME, req), 1))),
            ("response", (Nodetype.SEQUENCE, ((Nodetype.NAME, resp), 1))),
        ]),
        type_name: ([], [
            ("request_message", (Nodetype.NAME, req)),
            ("response_message", (Nodetype.NAME, resp)),
            ("event_message", (Nodetype.NAME, event)),
        ]),
    }  # fmt: skip


def _char_as_uint8(definition: Any) -> Any:
    """A rosbags field definition with every ``char`` base type read as ``uint8`` (rosidl's)."""
    if isinstance(definition, tuple):
        if len(definition) == 2 and definition[0] == "char" and isinstance(definition[1], int):
            return ("uint8", definition[1])
        return tuple(_char_as_uint8(part) for part in definition)
    if isinstance(definition, list):
        return [_char_as_uint8(part) for part in definition]
    return definition


class Ros2Types:
    """The ROS 2 types toploc speaks: rosbags' ROS 2 Jazzy store plus :data:`SERVICES` and
    ``toploc_msgs/msg/RoomBelief``. :meth:`message` makes one, :meth:`serialize` and
    :meth:`deserialize` are CDR (little-endian, with its 4-byte encapsulation header),
    :meth:`type_hash` is rosidl's RIHS01."""

    def __init__(self) -> None:
        self.store = get_typestore(Stores.ROS2_JAZZY)
        for name, (request, response) in SERVICES.items():
            self.store.register(service_definitions(name, request, response))
        self.store.register({ROOM_BELIEF: _msg_fields(room_belief_definition(), ROOM_BELIEF)})
        self._hashes: dict[str, str] = {}

    def register(self, definitions: dict[str, Any]) -> None:
        """Add rosbags type definitions (e.g. :func:`service_definitions`)."""
        self.store.register(definitions)
        self._hashes.clear()

    def type_hash(self, type_name: str) -> str:
        """The RIHS01 hash of ``type_name`` (a message or a service), rosidl's: ``char`` read
        as ``uint8``. ``KeyError`` for a type this store does not hold."""
        if type_name not in self._hashes:
            if type_name not in self.store.fielddefs:
                raise KeyError(f"no ROS 2 type {type_name!r} in toploc's type store")
            rosidl = Typestore()
            rosidl.fielddefs = {
                name: _char_as_uint8(definition)
                for name, definition in self.store.fielddefs.items()
            }
            self._hashes[type_name] = rosidl.hash_rihs01(type_name)
        return self._hashes[type_name]

    def message(self, type_name: str, **fields: Any) -> Any:
        """A message of ``type_name`` (rosbags' dataclass) with ``fields``."""
        return self.store.types[type_name](**fields)

    def serialize(self, message: Any, type_name: str) -> bytes:
        """``message`` as CDR bytes (little-endian, with the encapsulation header)."""
        return bytes(self.store.serialize_cdr(message, type_name))

    def deserialize(self, data: bytes, type_name: str) -> Any:
        """CDR ``data`` as a message of ``type_name``; ``ValueError`` naming the type and what
        is wrong for bytes that are not one."""
        try:
            return self.store.deserialize_cdr(data, type_name)
        except SerdeError as error:
            raise ValueError(f"not a CDR {type_name} ({len(data)} bytes): {error}") from None
