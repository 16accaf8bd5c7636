"""The key expressions of the bus: every key lives under ``toploc/<robot_id>/`` (:func:`key`);
the suffixes below are the contract's keys (the bus table in docs/bus.md), one constant each."""

from __future__ import annotations

import re
import socket

ROOT = "toploc"
FALLBACK_ROBOT_ID = "robot"

# Key suffixes under toploc/<robot_id>/ (see the bus table in docs/bus.md).
CAMERA_PANORAMA = "camera/panorama"
CAMERA_CAPTURE = "camera/capture"
BASE_CMD = "base/cmd"
BASE_STOP = "base/stop"
BASE_ODOM = "base/odom"
BASE_BUMPERS = "base/bumpers"
LOCALIZER_BELIEF = "localizer/belief"
LOCALIZER_LOCALIZE = "localizer/localize"
LOCALIZER_RESET = "localizer/reset"
MAP_ROOMS = "map/rooms"
MAP_PLACES = "map/places"
MAP_EDGES = "map/edges"
MAP_ADD = "map/add"
MAP_CONNECT = "map/connect"
MAP_CHANGED = "map/changed"
SIM_TRUE_POSE = "sim/true_pose"
"""Simulation only: the simulated base's true pose (:mod:`toploc.nodes.sim_truth`)."""
SIM_KIDNAP = "sim/kidnap"
"""Simulation only: carry the simulated base into a room (:mod:`toploc.nodes.sim_truth`)."""
HOMING_GOAL = "homing/goal"
HOMING_CANCEL = "homing/cancel"
HOMING_PROGRESS = "homing/progress"

_FORBIDDEN_CHUNK_CHARS = set("/*$?#")


def check_robot_id(robot_id: str) -> str:
    """Return ``robot_id`` if it is one non-empty key chunk (no ``/ * $ ? #``), else raise."""
    if not robot_id or _FORBIDDEN_CHUNK_CHARS & set(robot_id) or robot_id != robot_id.strip():
        raise ValueError(
            f"robot id must be a non-empty key chunk without '/', '*', '$', '?', '#' or "
            f"surrounding spaces, got {robot_id!r}"
        )
    return robot_id


def default_robot_id(hostname: str | None = None) -> str:
    """This machine's robot id: its host name (``socket.gethostname()``) up to the first dot,
    lower case, every character a key chunk forbids (``/ * $ ? #``, spaces) replaced by ``-``;
    ``"robot"`` if nothing is left. The service and the clients of one machine agree on it."""
    name = (socket.gethostname() if hostname is None else hostname).split(".")[0].lower()
    name = re.sub(r"[/*$?#\s]+", "-", name).strip("-")
    return name or FALLBACK_ROBOT_ID


def key(robot_id: str, suffix: str) -> str:
    """The key expression ``toploc/<robot_id>/<suffix>``, e.g. ``key("r1", LOCALIZER_BELIEF)``."""
    if not suffix or suffix.startswith("/") or suffix.endswith("/"):
        raise ValueError(f"key suffix must be relative like 'localizer/belief', got {suffix!r}")
    return f"{ROOT}/{check_robot_id(robot_id)}/{suffix}"


def alive_key(robot_id: str, node: str) -> str:
    """The liveliness token key of a node: ``toploc/<robot_id>/alive/<node>``."""
    return key(robot_id, f"alive/{check_robot_id(node)}")
