"""toploc's belief (the JSON of ``localizer/belief``, :func:`toploc.bus.messages.check_belief`)
as ROS 2 messages: the JSON itself as ``std_msgs/msg/String``, a
``diagnostic_msgs/msg/DiagnosticArray``, the typed ``toploc_msgs/msg/RoomBelief``, and the best
place's stored pose as ``geometry_msgs/msg/PoseWithCovarianceStamped``.

Frames: the map is topological, each room has a metric frame of its own, so the pose's
``header.frame_id`` is the best place's room and its position and heading are the place's, in
that frame (REP-103: x forward, y left, yaw counter-clockwise). It says where the panorama that
matched best was taken, not where the robot stands: the covariance says so
(:data:`PLACE_POSE_VARIANCE`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from toploc.bus.ros2.codec import (
    DIAGNOSTIC_ARRAY,
    POSE_WITH_COVARIANCE_STAMPED,
    ROOM_BELIEF,
    STRING,
    Ros2Types,
)

DIAGNOSTIC_NAME = "toploc: room localization"
# DiagnosticStatus levels (diagnostic_msgs/msg/DiagnosticStatus).
OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVEL_OF_STATE = {"localized": OK, "ambiguous": WARN, "homing": WARN, "lost": ERROR}
PLACE_POSE_VARIANCE = (1.0, 1.0, (math.pi / 4) ** 2)
"""The variances (m², m², rad²) of x, y and yaw in the pose's covariance: toploc knows which
place matched, not the robot's offset from it (a fixed, stated uncertainty, not an estimate);
z, roll and pitch are 0 (a planar robot)."""


def ros_time(types: Ros2Types, stamp_s: float | None) -> Any:
    """A ``builtin_interfaces/msg/Time`` of ``stamp_s`` (seconds since the UNIX epoch; 0 for
    none)."""
    nanoseconds = max(0, round((stamp_s or 0.0) * 1e9))
    sec, nanosec = divmod(nanoseconds, 1_000_000_000)
    return types.message("builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec)


def _header(types: Ros2Types, stamp_s: float | None, frame_id: str = "") -> Any:
    return types.message("std_msgs/msg/Header", stamp=ros_time(types, stamp_s), frame_id=frame_id)


def belief_string(types: Ros2Types, belief: Mapping[str, Any]) -> Any:
    """The belief's JSON (as toploc publishes it, ``stale`` and ``age_s`` included) as a
    ``std_msgs/msg/String``."""
    return types.message(STRING, data=json.dumps(belief, sort_keys=True))


def summary(belief: Mapping[str, Any]) -> str:
    """One line: the state, the top room and its probability, e.g. ``localized: kitchen
    (p 0.93)``; ``stale`` in front while the belief is stale."""
    top = belief.get("top") or {}
    text = f"{belief['state']}: {top.get('room', '?')} (p {top.get('probability', 0.0):.2f})"
    return f"stale, {text}" if belief.get("stale") else text


def belief_diagnostics(types: Ros2Types, belief: Mapping[str, Any], hardware_id: str) -> Any:
    """A ``diagnostic_msgs/msg/DiagnosticArray`` of one status: level OK (localized), WARN
    (ambiguous, homing), ERROR (lost) or STALE; the summary as its message; the state, top
    room, probability, entropy and stale flag as its values, and ``partly_seen`` (``room
    share needed``: why a belief sure by its odds waits) when the belief has it."""
    top = belief.get("top") or {}
    values = {
        "state": str(belief["state"]),
        "top_room": str(top.get("room", "")),
        "probability": f"{top.get('probability', 0.0):.6f}",
        "entropy_bits": f"{belief['entropy_bits']:.6f}",
        "stale": "true" if belief.get("stale") else "false",
    }
    seen = belief.get("partly_seen")
    if seen is not None:
        values["partly_seen"] = (
            f"{seen['room']} {seen['horizon_share']:.3f} {seen['needed_share']:.3f}"
        )
    level = STALE if belief.get("stale") else LEVEL_OF_STATE.get(str(belief["state"]), ERROR)
    status = types.message(
        "diagnostic_msgs/msg/DiagnosticStatus",
        level=level,
        name=DIAGNOSTIC_NAME,
        message=summary(belief),
        hardware_id=hardware_id,
        values=[
            types.message("diagnostic_msgs/msg/KeyValue", key=key, value=value)
            for key, value in values.items()
        ],
    )
    return types.message(
        DIAGNOSTIC_ARRAY, header=_header(types, belief.get("stamp")), status=[status]
    )


def room_belief(types: Ros2Types, belief: Mapping[str, Any]) -> Any:
    """The belief as a ``toploc_msgs/msg/RoomBelief`` (fields in ``RoomBelief.msg``; rosbags
    takes a ``float64[]`` as a numpy array)."""
    rooms = belief["rooms"]
    best = belief.get("best_place") or {}
    return types.message(
        ROOM_BELIEF,
        stamp=ros_time(types, belief.get("stamp")),
        state=str(belief["state"]),
        rooms=list(rooms),
        probabilities=np.asarray([float(p) for p in rooms.values()], dtype=np.float64),
        entropy_bits=float(belief["entropy_bits"]),
        best_room=str(best.get("room") or ""),
        best_place_id=int(best["place_id"]) if best.get("place_id") is not None else -1,
        best_place_inliers=int(best.get("inliers") or 0),
        stale=bool(belief.get("stale", False)),
    )


def place_pose(types: Ros2Types, belief: Mapping[str, Any], place: Mapping[str, Any]) -> Any | None:
    """The stored pose of the belief's best ``place`` (a ``map/places`` entry) as a
    ``geometry_msgs/msg/PoseWithCovarianceStamped`` in the frame of its room; ``None`` when the
    place has no position (a map recorded without poses). A place without a heading has yaw 0
    and the largest yaw variance ((2π)², as unknown)."""
    if place.get("x_m") is None or place.get("y_m") is None:
        return None
    heading_deg = place.get("heading_deg")
    yaw_rad = math.radians(heading_deg) if heading_deg is not None else 0.0
    var_x, var_y, var_yaw = PLACE_POSE_VARIANCE
    if heading_deg is None:
        var_yaw = (2 * math.pi) ** 2
    covariance = np.zeros(36, dtype=np.float64)
    covariance[0], covariance[7], covariance[35] = var_x, var_y, var_yaw
    pose = types.message(
        "geometry_msgs/msg/Pose",
        position=types.message(
            "geometry_msgs/msg/Point", x=float(place["x_m"]), y=float(place["y_m"]), z=0.0
        ),
        orientation=types.message(
            "geometry_msgs/msg/Quaternion",
            x=0.0,
            y=0.0,
            z=math.sin(yaw_rad / 2),
            w=math.cos(yaw_rad / 2),
        ),
    )
    return types.message(
        POSE_WITH_COVARIANCE_STAMPED,
        header=_header(types, belief.get("stamp"), str(place["room"])),
        pose=types.message(
            "geometry_msgs/msg/PoseWithCovariance", pose=pose, covariance=covariance
        ),
    )
