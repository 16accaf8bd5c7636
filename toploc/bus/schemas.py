"""Every JSON message of the bus, declared once: its ``kind`` and its fields' JSON types.

A :class:`Schema`'s ``fields`` are those every reader requires (``float`` accepts a JSON integer;
``(float, type(None))`` allows null); ``optional`` those a message may leave out, checked where
a reader says so (:meth:`Schema.check_optional`). The keys are :mod:`toploc.bus.keys`'; the
bus table in docs/bus.md describes each message. Conversions from and to toploc's own types
(odometry, belief, homing results) are :mod:`toploc.bus.messages`'.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from toploc.bus.json_codec import FieldType, check_fields, decode, encode

NULL = type(None)


@dataclass(frozen=True)
class Schema:
    """One message: ``{"schema": 1, "kind": kind, **fields}``."""

    kind: str
    fields: Mapping[str, FieldType] = field(default_factory=dict)
    optional: Mapping[str, FieldType] = field(default_factory=dict)

    def encode(self, values: Mapping[str, Any]) -> bytes:
        """``values`` as this message's UTF-8 JSON (:func:`~toploc.bus.json_codec.encode`)."""
        return encode(self.kind, values)

    def decode(
        self,
        key_expr: str,
        data: bytes | None,
        check_kind: bool = True,
        max_bytes: int | None = None,
        max_string_chars: int | None = None,
    ) -> dict[str, Any]:
        """The message in ``data`` received on ``key_expr``, its envelope and ``fields`` checked
        (its kind too if ``check_kind``); :class:`~toploc.bus.errors.BusMessageError` else."""
        kind = self.kind if check_kind else None
        return decode(key_expr, data, self.fields, kind, max_bytes, max_string_chars)

    def check_optional(self, where: str, message: Mapping[str, Any]) -> None:
        """Check the ``optional`` fields ``message`` carries (prefixed ``where``)."""
        check_fields(where, message, {k: t for k, t in self.optional.items() if k in message})


# --- the base and the camera: toploc.nodes.robot, toploc.nodes.camera ----------------------

CMD = Schema("cmd", {"turn_deg": float, "forward_m": float})
"""``base/cmd`` request: turn, then drive forward (degrees, metres)."""
ODOM = Schema("odom", {"x_m": float, "y_m": float, "heading_deg": float, "stamp": float})
"""``base/odom``: the odometry pose (REP-103, metres and degrees) and its stamp (epoch s)."""
MOVE = Schema("move", {"turned_deg": float, "moved_m": float, "bumped": bool, "odom": dict})
"""``base/cmd`` reply: what the move did; ``odom`` holds the :data:`ODOM` fields after it."""
BUMPERS = Schema("bumpers", {"bumped": bool, "stamp": float})
"""``base/bumpers`` publication after each move."""
STOP = Schema("stop")
"""``base/stop`` request."""
STOPPED = Schema("stopped", {"stopped": bool})
"""``base/stop`` reply."""
CAPTURE = Schema(
    "capture", {"capture_id": int, "stamp": float, "heading_deg": float, "source": str}
)
"""The JSON attachment of a ``camera/capture`` reply and a ``camera/panorama`` publication."""

# --- the localizer: toploc.nodes.localizer --------------------------------------------------

BELIEF = Schema(
    "belief",
    optional={"stale": bool, "age_s": (float, NULL), "map_age_s": (float, NULL), "active": dict},
)
"""``localizer/belief``: :meth:`localizer.belief.RoomBelief.to_json`'s fields, checked by
:func:`toploc.bus.messages.check_belief`; a stale belief adds ``stale`` and ``age_s``, a
localizer on a replica of a site map ``map_age_s`` (seconds since the replica last confirmed
it was the map's current version; null: never); the reply to an active ``localize`` adds
``active`` (:data:`ACTIVE`)."""

ACTIVE = Schema("active", {"drives": int, "distance_m": float, "ended": str})
"""The ``active`` field of an active ``localize`` reply (:func:`toploc.runner.active_summary`):
drives, odometric metres, and why it ended (a key of :data:`localizer.active.ENDINGS`)."""
LOCALIZE = Schema("localize", optional={"active": bool, "timeout_s": float})
"""``localizer/localize`` request (optional: no payload at all is a passive localize)."""
RESET = Schema("reset", optional={"prior": dict})
"""``localizer/reset`` request; ``prior``: ``{room: p}`` (see :mod:`toploc.bus.messages`)."""

# --- the map: toploc.nodes.mapdb ------------------------------------------------------------

ROOMS = Schema("rooms", {"rooms": list})
"""``map/rooms`` reply: ``[{id, name, n_places}]``."""
PLACES_QUERY = Schema("places", optional={"room": str})
"""``map/places`` request (optional; its kind is not checked)."""
PLACES = Schema("places", {"places": list})
"""``map/places`` reply: the places' fields."""
EDGES = Schema("edges", {"edges": list})
"""``map/edges`` reply: ``[[room_a, room_b]]``."""
ADD = Schema(
    "add",
    {"room": str},
    {
        "x_m": (float, NULL),
        "y_m": (float, NULL),
        "heading_deg": (float, NULL),
        "leg_from": (int, NULL),
        "leg_via": (list, NULL),
    },
)
"""``map/add`` request: the JSON attachment of the PNG payload (pose in the room's frame, or
in the odometry frame of a drive: then ``leg_from`` names the place recorded before on that
drive and ``leg_via`` the odometry positions ``[[x_m, y_m], ...]`` driven between)."""
ADDED = Schema(
    "added",
    {"place_id": int, "room": str, "new": bool, "fingerprints": dict},
    {"refresh_after_s": (float, NULL)},
)
"""``map/add`` reply; ``fingerprints`` ``{detector: n}``."""
CONNECT = Schema("connect", {"room_a": str, "room_b": str})
"""``map/connect`` request."""
CONNECTED = Schema("connected", {"room_a": str, "room_b": str, "added": bool})
"""``map/connect`` reply (a client reads ``added`` only)."""
CHANGED = Schema("changed", {"what": str}, {"stamp": float, "version": int, "map_id": str})
"""``map/changed`` publication after each write; ``what``: ``add`` or ``connect`` (a map node's
write), ``replica`` (a site robot's replica took the site map's changes); the map's version
after it and its id (a site map's ``changed`` and a replica's always carry them)."""

# --- a site's shared map: toploc.nodes.mapdb (site keys), toploc.replication -----------------

MAP_VERSION = Schema("map_version", {"map_id": str, "version": int}, {"stamp": float})
"""``version`` reply: the map's id and current version."""
SNAPSHOT_CHUNK = Schema(
    "snapshot_chunk",
    {
        "map_id": str,
        "version": int,
        "index": int,
        "n_chunks": int,
        "total_bytes": int,
        "sha256": str,
    },
)
"""The JSON attachment of each reply to ``snapshot`` (one reply per chunk; the payload is the
chunk's bytes of :func:`mapdb.replication.encode_snapshot`, ``sha256`` that of all of them)."""
CHANGES_QUERY = Schema("changes", {"after": int})
"""``changes`` request: the changes after version ``after``."""
CHANGES_BATCH = Schema("changes_batch", {"map_id": str, "version": int, "more": bool})
"""The JSON attachment of the ``changes`` reply (payload: :func:`mapdb.replication.
encode_changes`); ``version``: the map's current one, ``more``: ask again after the last."""

# --- homing: toploc.nodes.homing ------------------------------------------------------------

GOAL = Schema("goal", {"place_id": int}, {"timeout_s": float})
"""``homing/goal`` request (``timeout_s`` > 0, checked by the node)."""
HOMING_RESULT = Schema(
    "homing",
    {"place_id": int, "arrived": bool, "reason": str, "steps": int, "distance_m": float},
)
"""``homing/goal`` reply."""
CANCEL = Schema("cancel")
"""``homing/cancel`` request (optional)."""
CANCELLED = Schema("cancelled", {"cancelled": bool})
"""``homing/cancel`` reply: whether a drive was running."""
PROGRESS = Schema(
    "progress",
    {"place_id": int},
    {
        "step": int,
        "features": int,
        "matched": int,
        "home_length": (float, NULL),
        "parallax_deg": (float, NULL),
        "moved_m": float,
        "state": str,
    },
)
"""``homing/progress`` publication after each capture of a drive, and once at its end."""

# --- the simulation only: toploc.nodes.sim_truth --------------------------------------------

TRUE_POSE = Schema(
    "true_pose",
    {
        "x_m": float,
        "y_m": float,
        "heading_deg": float,
        "world": str,
        "room": (str, NULL),
        "stamp": float,
    },
)
"""``sim/true_pose``: the simulated base's pose in the building frame of ``world``."""
KIDNAP = Schema("kidnap", {"room": str})
"""``sim/kidnap`` request; the reply is a :data:`TRUE_POSE`."""

# --- every key ------------------------------------------------------------------------------

ERROR = Schema("error", {"error": str}, {"retry_after_s": float})
"""An error reply (``Query.reply_err``); ``retry_after_s``: a refusal for now (a rate limit)."""
