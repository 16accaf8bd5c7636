"""Pure conversion between a :class:`Fingerprint` and the columns of a ``fingerprints`` row,
and between a :class:`Leg` and a ``legs`` row.

Arrays are stored as raw little-endian blobs, so reading them back is one ``np.frombuffer`` each
(no parsing): keypoints ``(n, 2)`` float32, bearings ``(n,)`` float64, descriptors ``(n, d)``,
the keypoints' sizes ``(n,)`` float32 (NULL where not known).
Descriptors are stored as ``uint8`` (``descriptor_dtype = 'u1'``, a quarter of the size) when
every value is an integer in [0, 255], as OpenCV's SIFT descriptors are, else as float32
(``'f4'``); both load back as the same float32 values. The row also carries ``n_keypoints`` and
``descriptor_dim`` to reshape, the ALV, and the extraction parameters as JSON. No SQLite here:
rows are plain dicts and tuples.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from homing.alv import alv_from_bearings
from mapdb.records import Fingerprint, Leg, ParamValue

KEYPOINTS_DTYPE = np.dtype("<f4")
BEARINGS_DTYPE = np.dtype("<f8")
DESCRIPTORS_DTYPE = np.dtype("<f4")
SIZES_DTYPE = np.dtype("<f4")
DESCRIPTOR_STORAGE: dict[str, np.dtype[Any]] = {"u1": np.dtype("u1"), "f4": DESCRIPTORS_DTYPE}
"""Stored descriptor element types by their ``descriptor_dtype`` code."""


def stored_alv(bearings_rad: np.ndarray) -> np.ndarray:
    """The ALV stored in a row's ``alv_x``, ``alv_y``: :func:`homing.alv.alv_from_bearings`.

    ``bearings_rad`` is ``(n,)`` in radians (REP-103, CCW from the heading); the ALV is a float64
    2-vector ``(x, y)`` in the robot frame (unitless, norm <= 1). A fingerprint with no keypoints
    has no ALV (homing raises :class:`homing.alv.HomingError`), but the columns are NOT NULL and
    maps have always stored ``(0, 0)`` for it, so it keeps ``(0, 0)``.
    """
    bearings = np.asarray(bearings_rad, dtype=np.float64)
    if bearings.size == 0:
        return np.zeros(2)  # no keypoints: the stored ALV stays (0, 0)
    return alv_from_bearings(bearings)


def descriptor_storage(descriptors: np.ndarray) -> str:
    """``'u1'`` if every value is an integer in [0, 255] (lossless as uint8), else ``'f4'``."""
    values = np.asarray(descriptors)
    if values.size == 0 or values.dtype == np.uint8:
        return "u1"
    exact = np.all((values >= 0) & (values <= 255) & (values == np.rint(values)))
    return "u1" if exact else "f4"


def decode_descriptors(blob: bytes, code: str, n_keypoints: int, dim: int) -> np.ndarray:
    """``(n, dim)`` float32 descriptors from a blob stored as ``code`` (``'u1'`` or ``'f4'``)."""
    values = np.frombuffer(blob, DESCRIPTOR_STORAGE[code])
    if code != "f4":
        values = values.astype(DESCRIPTORS_DTYPE)
    return values.reshape(n_keypoints, dim)


def params_to_json(params: Mapping[str, ParamValue]) -> str:
    """Extraction parameters as canonical JSON (sorted keys), so equal params give equal text."""
    return json.dumps(dict(params), sort_keys=True)


def fingerprint_to_row(fingerprint: Fingerprint) -> dict[str, Any]:
    """Columns of a ``fingerprints`` row for ``fingerprint`` (without ``place_id``).

    Raises ``ValueError`` naming the shape when descriptors are not a 2-D array.
    """
    descriptors = np.asarray(fingerprint.descriptors)
    if descriptors.ndim != 2:
        raise ValueError(
            f"descriptors of detector {fingerprint.detector!r} must be 2-D (n, d), "
            f"got shape {descriptors.shape}"
        )
    alv = stored_alv(fingerprint.bearings_rad)  # (0, 0) for a fingerprint with no keypoints
    code = descriptor_storage(descriptors)
    return {
        "detector": fingerprint.detector,
        "n_keypoints": fingerprint.n,
        "descriptor_dim": int(descriptors.shape[1]),
        "keypoints_xy": np.ascontiguousarray(fingerprint.keypoints_xy, KEYPOINTS_DTYPE).tobytes(),
        "bearings_rad": np.ascontiguousarray(fingerprint.bearings_rad, BEARINGS_DTYPE).tobytes(),
        "descriptor_dtype": code,
        "descriptors": np.ascontiguousarray(descriptors, DESCRIPTOR_STORAGE[code]).tobytes(),
        "alv_x": float(alv[0]),
        "alv_y": float(alv[1]),
        "params_json": params_to_json(fingerprint.params),
        "keypoint_sizes_px": None
        if fingerprint.keypoint_sizes_px is None
        else np.ascontiguousarray(fingerprint.keypoint_sizes_px, SIZES_DTYPE).tobytes(),
    }


class ParamsCache:
    """Decodes ``params_json`` once per distinct text (a map usually has one per detector)."""

    def __init__(self) -> None:
        self._decoded: dict[str, Mapping[str, ParamValue]] = {}

    def __call__(self, params_json: str) -> Mapping[str, ParamValue]:
        """The decoded mapping for ``params_json`` (shared between rows; do not mutate)."""
        params = self._decoded.get(params_json)
        if params is None:
            params = json.loads(params_json)
            self._decoded[params_json] = params
        return params


def fingerprint_from_row(
    detector: str,
    image_width_px: int,
    image_height_px: int,
    n_keypoints: int,
    descriptor_dim: int,
    keypoints_blob: bytes,
    bearings_blob: bytes,
    descriptor_dtype: str,
    descriptors_blob: bytes,
    params: Mapping[str, ParamValue],
    sizes_blob: bytes | None = None,
) -> Fingerprint:
    """Rebuild a :class:`Fingerprint` from row values (keypoints, bearings and sizes: read-only
    views; ``sizes_blob`` None: sizes not known)."""
    return Fingerprint(
        detector=detector,
        image_width_px=image_width_px,
        image_height_px=image_height_px,
        keypoints_xy=np.frombuffer(keypoints_blob, KEYPOINTS_DTYPE).reshape(n_keypoints, 2),
        bearings_rad=np.frombuffer(bearings_blob, BEARINGS_DTYPE),
        descriptors=decode_descriptors(
            descriptors_blob, descriptor_dtype, n_keypoints, descriptor_dim
        ),
        params=params,
        keypoint_sizes_px=None if sizes_blob is None else np.frombuffer(sizes_blob, SIZES_DTYPE),
    )


def via_to_json(leg: Leg) -> str:
    """A leg's via points as the ``legs.via_json`` text: ``[[x_m, y_m], ...]``."""
    return json.dumps([list(point) for point in leg.via_xy_m], separators=(",", ":"))


def leg_from_row(from_place_id: int, via_json: str) -> Leg:
    """The :class:`Leg` a ``legs`` row stores; ``ValueError`` saying what is wrong if its
    ``via_json`` is not a list of ``[x_m, y_m]`` pairs of finite numbers."""
    try:
        points = json.loads(via_json)
    except json.JSONDecodeError as error:
        raise ValueError(f"via_json is not JSON ({error})") from None
    if not isinstance(points, list) or not all(isinstance(p, list) for p in points):
        raise ValueError(f"via_json must be a list of [x_m, y_m] pairs, got {via_json[:60]!r}")
    return Leg(from_place_id, tuple(tuple(point) for point in points))
