"""Messages to and from toploc's own types: the odometry of ``base/odom``, the belief of
``localizer/belief`` (and its stale marks), the prior of ``localizer/reset``, the homing
result and progress of ``homing/goal`` and ``homing/progress``. The messages' kinds and fields
are :mod:`toploc.bus.schemas`'."""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from localizer.belief import RoomBelief
from localizer.robot_protocol import Pose2D
from toploc.bus.errors import BusMessageError
from toploc.bus.json_codec import check_fields, has_type
from toploc.bus.schemas import ACTIVE, BELIEF

if TYPE_CHECKING:
    from localizer.visual_homing import HomingProgress, HomingResult


def odometry_fields(odometry: Pose2D, stamp_s: float) -> dict[str, float]:
    """The ``base/odom`` fields of ``odometry`` (heading in degrees, stamp in seconds)."""
    return {
        "x_m": odometry.x_m,
        "y_m": odometry.y_m,
        "heading_deg": math.degrees(odometry.heading_rad),
        "stamp": stamp_s,
    }


def odometry_from_fields(message: Mapping[str, Any]) -> Pose2D:
    """Inverse of :func:`odometry_fields` (on a checked message)."""
    return Pose2D(message["x_m"], message["y_m"], math.radians(message["heading_deg"]))


def check_belief(where: str, belief: Mapping[str, Any]) -> dict[str, Any]:
    """The belief message (``RoomBelief.to_json()``) ``belief`` stands for, checked field by
    field, with the optional ``stale`` (bool), ``age_s`` (a number >= 0, or null),
    ``map_age_s`` and ``active`` (:data:`~toploc.bus.schemas.ACTIVE`'s fields) kept;
    :class:`~toploc.bus.errors.BusMessageError` prefixed ``where`` naming the bad field."""
    try:
        checked = RoomBelief.from_json(belief).to_json()
    except ValueError as error:
        raise BusMessageError(f"{where}: {error}") from None
    BELIEF.check_optional(where, belief)
    if belief.get("age_s") is not None and belief["age_s"] < 0:
        raise BusMessageError(f"{where}: field 'age_s' must be >= 0, got {belief['age_s']!r}")
    if "active" in belief:
        check_fields(f"{where}: field 'active'", belief["active"], ACTIVE.fields)
    return {**checked, **{k: belief[k] for k in BELIEF.optional if k in belief}}


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
        raise BusMessageError(
            f"{where}: prior must be a non-empty object {{room: p}}, got {prior!r}"
        )
    for room, p in prior.items():
        if not has_type(p, float) or p < 0:
            raise BusMessageError(f"{where}: prior[{room!r}] must be a number >= 0, got {p!r}")
    return {room: float(p) for room, p in prior.items()}


def progress_message(place_id: int, progress: HomingProgress) -> dict[str, Any]:
    """The ``homing/progress`` fields for one capture (see :mod:`toploc.nodes.homing`)."""
    home = progress.home
    parallax = None if home is None or math.isnan(home.parallax_rad) else home.parallax_rad
    return {
        "place_id": place_id,
        "step": progress.steps,
        "features": progress.view.n,
        "matched": 0 if home is None else home.n_used,
        "home_length": None if home is None else home.length,
        "parallax_deg": None if parallax is None else math.degrees(parallax),
        "moved_m": progress.distance_m,
        "state": "lost" if home is None else "homing",
    }


def progress_defaults(place_id: int) -> dict[str, Any]:
    """A ``homing/progress`` message before any capture."""
    return {
        "place_id": place_id,
        "step": 0,
        "features": 0,
        "matched": 0,
        "home_length": None,
        "parallax_deg": None,
        "moved_m": 0.0,
        "state": "homing",
    }


def result_message(place_id: int, result: HomingResult) -> dict[str, Any]:
    """The ``homing/goal`` reply fields."""
    return {
        "place_id": place_id,
        "arrived": result.arrived,
        "reason": result.reason,
        "steps": result.steps,
        "distance_m": result.distance_m,
    }
