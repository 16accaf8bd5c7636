"""The key expressions of the bus: a robot's keys live under ``toploc/<robot_id>/`` (:func:`key`);
the suffixes below are the contract's keys (the bus table in docs/bus.md), one constant each.

A site's shared map (issue 22) has keys of its own under ``toploc/map/<map_id>/``
(:func:`site_key`): the map's ``map/*`` keys without their ``map/`` (``toploc/map/site-1/add``)
and the replication keys :data:`SITE_VERSION`, :data:`SITE_SNAPSHOT`, :data:`SITE_CHANGES`.
``map`` is therefore no robot id."""

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
SITE_ROOT = "map"
"""``toploc/map/<map_id>/``: a site's shared map (:func:`site_key`); not a robot id."""
SITE_VERSION = "version"
SITE_SNAPSHOT = "snapshot"
SITE_CHANGES = "changes"
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
    if robot_id == SITE_ROOT:
        raise ValueError(f"robot id {SITE_ROOT!r} is taken: toploc/{SITE_ROOT}/ holds site maps")
    return robot_id


def check_map_id(map_id: str) -> str:
    """Return ``map_id`` if it is one non-empty key chunk (no ``/ * $ ? #``), else raise."""
    if not map_id or _FORBIDDEN_CHUNK_CHARS & set(map_id) or map_id != map_id.strip():
        raise ValueError(
            f"map id must be a non-empty key chunk without '/', '*', '$', '?', '#' or "
            f"surrounding spaces, got {map_id!r}"
        )
    return map_id


def site_key(map_id: str, suffix: str) -> str:
    """The key of site map ``map_id``: ``toploc/map/<map_id>/<suffix>``, where a robot's map key
    (``map/add``) loses its ``map/``: ``site_key("site-1", MAP_ADD) == "toploc/map/site-1/add"``."""
    return f"{ROOT}/{SITE_ROOT}/{check_map_id(map_id)}/{suffix.removeprefix('map/')}"


def site_alive_key(map_id: str, node: str) -> str:
    """The liveliness token of site map ``map_id``'s node: ``toploc/map/<map_id>/alive/<node>``."""
    return site_key(map_id, f"alive/{check_robot_id(node)}")


def default_robot_id(hostname: str | None = None) -> str:
    """This machine's robot id: its host name (``socket.gethostname()``) up to the first dot,
    lower case, every character a key chunk forbids (``/ * $ ? #``, spaces) replaced by ``-``;
    ``"robot"`` if nothing is left. The service and the clients of one machine agree on it."""
    name = (socket.gethostname() if hostname is None else hostname).split(".")[0].lower()
    name = re.sub(r"[/*$?#\s]+", "-", name).strip("-")
    return name if name and name != SITE_ROOT else FALLBACK_ROBOT_ID


def key(robot_id: str, suffix: str) -> str:
    """The key expression ``toploc/<robot_id>/<suffix>``, e.g. ``key("r1", LOCALIZER_BELIEF)``."""
    if not suffix or suffix.startswith("/") or suffix.endswith("/"):
        raise ValueError(f"key suffix must be relative like 'localizer/belief', got {suffix!r}")
    return f"{ROOT}/{check_robot_id(robot_id)}/{suffix}"


def alive_key(robot_id: str, node: str) -> str:
    """The liveliness token key of a node: ``toploc/<robot_id>/alive/<node>``."""
    return key(robot_id, f"alive/{check_robot_id(node)}")
