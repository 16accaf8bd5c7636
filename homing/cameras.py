"""Camera models of 360° panoramas: each maps a pixel to a unit ray in the robot frame and back.

The one camera model toploc has: the localizer's features and rays, the map's fingerprints
(:attr:`mapdb.records.Fingerprint.camera`) and the renderer (:mod:`robot.render`) all use these
types, built by the one factory :func:`camera_model` (or, from a fingerprint's extraction
parameters, :func:`camera_from_params`). It stands on the ground floor beside the azimuth
convention it extends (:mod:`homing.bearings`), so a fingerprint can carry its camera.

Frames and conventions (DESIGN.md, REP-103: x forward, y left, z up, angles CCW positive):
OpenCV pixel coordinates put pixel centres at integers, rows grow downwards. Every panorama is
``W`` columns for 360°: column 0 looks along the robot's heading and columns increase clockwise,
so a column ``x`` has azimuth ``-2*pi*x/W``. Elevation is positive above the horizon; the models
differ only in how rows map to elevations:

- :class:`Cylinder`: rows on a cylinder of radius ``focal_px`` around the camera,
  ``elevation = atan((horizon - y) / f)`` (the panoramas toploc renders and stitches, and an
  unwrapped omnidirectional mirror image, :class:`localizer.cameras.MirrorUnwrap`).
- :class:`Equirect`: the whole sphere, ``H = W / 2`` rows for 180°, linear in elevation,
  ``elevation = pi * ((H - 1) / 2 - y) / H`` (what Ricoh Theta, Insta360 and most 360°
  cameras write).

Pure numpy: scalars or arrays in, float arrays out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from homing.bearings import bearing_rad_from_column, check_width_px, column_from_bearing

CAMERA_MODELS: tuple[str, ...] = ("cylinder", "equirect")
"""The names of the camera models (``camera`` in a fingerprint's extraction parameters)."""

ParamValue = float | int | str | bool
"""A value of an extraction parameter (as :data:`mapdb.records.ParamValue`, which is this)."""


def _check_height(height_px: int) -> None:
    if int(height_px) != height_px or height_px < 1:
        raise ValueError(f"panorama height must be a positive integer, got {height_px!r}")


def rays_from_angles(bearing_rad: ArrayLike, elevation_rad: ArrayLike) -> np.ndarray:
    """(n, 3) float64 unit rays in the robot frame from azimuths and elevations (rad)."""
    b = np.asarray(bearing_rad, dtype=np.float64).reshape(-1)
    e = np.asarray(elevation_rad, dtype=np.float64).reshape(-1)
    if b.shape != e.shape:
        raise ValueError(f"{b.shape[0]} bearings but {e.shape[0]} elevations")
    cos_e = np.cos(e)
    return np.stack([cos_e * np.cos(b), cos_e * np.sin(b), np.sin(e)], axis=1)


def focal_from_vfov_px(height_px: int, vfov_deg: float) -> float:
    """The cylinder radius (px) at which ``height_px`` rows span ``vfov_deg`` degrees from the
    top edge to the bottom edge of the image: ``(H / 2) / tan(vfov / 2)``."""
    if not 0 < vfov_deg < 180:
        raise ValueError(f"vfov_deg must be in (0, 180), got {vfov_deg}")
    return (height_px / 2.0) / math.tan(math.radians(vfov_deg) / 2.0)


@dataclass(frozen=True)
class Cylinder:
    """A cylindrical panorama of ``width_px`` x ``height_px``.

    ``focal_px`` is the cylinder radius in pixels (distance from the projection centre to the
    image surface). ``None`` assumes square pixels on the cylinder, ``W / (2*pi)``: one column is
    as wide in angle as one row is high at the horizon. Unwrapped mirror images are not true
    cylinders (rows follow the mirror profile); pass a calibrated focal length for them.
    ``horizon_row_px`` is the row coordinate of zero elevation; ``None`` means the image centre
    row ``(H - 1) / 2``.
    """

    width_px: int
    height_px: int
    focal_px: float | None = None
    horizon_row_px: float | None = None
    kind: ClassVar[str] = "cylinder"

    def __post_init__(self) -> None:
        check_width_px(self.width_px)
        _check_height(self.height_px)
        if self.focal_px is not None and not (np.isfinite(self.focal_px) and self.focal_px > 0):
            raise ValueError(f"focal_px must be a positive finite number, got {self.focal_px!r}")
        if self.horizon_row_px is not None and not np.isfinite(self.horizon_row_px):
            raise ValueError(f"horizon_row_px must be finite, got {self.horizon_row_px!r}")

    @property
    def f_px(self) -> float:
        """The focal length in pixels actually used (the default resolved)."""
        return float(self.width_px / (2.0 * np.pi) if self.focal_px is None else self.focal_px)

    @property
    def horizon_px(self) -> float:
        """The horizon row coordinate actually used (the default resolved)."""
        return float(
            (self.height_px - 1) / 2.0 if self.horizon_row_px is None else self.horizon_row_px
        )

    @property
    def pixel_rad(self) -> float:
        """Angular size (rad) of a pixel at the horizon: the larger of its width and height."""
        return max(2.0 * np.pi / self.width_px, 1.0 / self.f_px)

    def elevation_rad(self, y_px: ArrayLike) -> np.ndarray:
        """Elevation (rad, positive up) of row coordinate ``y_px``: a point ``h - y`` pixels
        above the horizon row ``h`` of a cylinder of radius ``f`` is seen at ``atan((h - y)/f)``."""
        return np.arctan2(self.horizon_px - np.asarray(y_px, dtype=float), self.f_px)

    def tan_elevation(self, y_px: ArrayLike) -> np.ndarray:
        """``tan`` of the elevation of row coordinate ``y_px``, ``(h - y) / f`` (the height per
        metre of horizontal distance of its ray)."""
        return (self.horizon_px - np.asarray(y_px, dtype=float)) / self.f_px

    def row_px(self, elevation_rad: ArrayLike) -> np.ndarray:
        """Row coordinate at which ``elevation_rad`` (in (-pi/2, pi/2)) is imaged."""
        return self.horizon_px - self.f_px * np.tan(np.asarray(elevation_rad, dtype=float))

    def params(self) -> dict[str, ParamValue]:
        """What a fingerprint records of this camera (see :func:`camera_from_params`)."""
        record: dict[str, ParamValue] = {"camera": self.kind}
        if self.focal_px is not None:
            record["focal_px"] = float(self.focal_px)
        if self.horizon_row_px is not None:
            record["horizon_row_px"] = float(self.horizon_row_px)
        return record


@dataclass(frozen=True)
class Equirect:
    """An equirectangular panorama of ``width_px`` x ``height_px`` (the full sphere: 360° by
    180°, normally ``W = 2 H``); rows are linear in elevation, row 0 next to the zenith."""

    width_px: int
    height_px: int
    kind: ClassVar[str] = "equirect"

    def __post_init__(self) -> None:
        check_width_px(self.width_px)
        _check_height(self.height_px)

    @property
    def horizon_px(self) -> float:
        """The row coordinate of the horizon, ``(H - 1) / 2``."""
        return (self.height_px - 1) / 2.0

    @property
    def pixel_rad(self) -> float:
        """Angular height (rad) of a row, ``pi / H``."""
        return math.pi / self.height_px

    def elevation_rad(self, y_px: ArrayLike) -> np.ndarray:
        """Elevation (rad, positive up) of row coordinate ``y_px``: ``pi * (h - y) / H``."""
        return np.pi * (self.horizon_px - np.asarray(y_px, dtype=float)) / self.height_px

    def tan_elevation(self, y_px: ArrayLike) -> np.ndarray:
        """``tan`` of the elevation of row coordinate ``y_px`` (the height per metre of
        horizontal distance of its ray)."""
        return np.tan(self.elevation_rad(y_px))

    def row_px(self, elevation_rad: ArrayLike) -> np.ndarray:
        """Row coordinate at which ``elevation_rad`` (in [-pi/2, pi/2]) is imaged."""
        return self.horizon_px - np.asarray(elevation_rad, dtype=float) * self.height_px / np.pi

    def params(self) -> dict[str, ParamValue]:
        """What a fingerprint records of this camera (see :func:`camera_from_params`)."""
        return {"camera": self.kind}


CameraModel = Cylinder | Equirect


def camera_model(
    kind: str,
    width_px: int,
    height_px: int,
    focal_px: float | None = None,
    horizon_row_px: float | None = None,
) -> CameraModel:
    """The camera model ``kind`` (one of :data:`CAMERA_MODELS`) of a ``width_px`` x
    ``height_px`` panorama; ``focal_px`` and ``horizon_row_px`` are a cylinder's (see
    :class:`Cylinder`) and must be None for a sphere."""
    if kind == "equirect":
        if focal_px is not None or horizon_row_px is not None:
            raise ValueError("an equirect camera has no focal_px or horizon_row_px")
        return Equirect(int(width_px), int(height_px))
    if kind != "cylinder":
        raise ValueError(f"unknown camera {kind!r}: expected one of {CAMERA_MODELS}")
    return Cylinder(int(width_px), int(height_px), focal_px, horizon_row_px)


def camera_from_params(
    width_px: int, height_px: int, params: Mapping[str, ParamValue]
) -> CameraModel:
    """The camera of a ``width_px`` x ``height_px`` panorama whose extraction ``params`` record
    ``camera`` (absent in maps made before cameras were recorded: a cylinder), and for a
    cylinder ``focal_px`` and ``horizon_row_px`` when known (:func:`camera_model`)."""
    kind = str(params.get("camera", "cylinder"))
    if kind == "equirect":
        return camera_model(kind, width_px, height_px)
    focal = params.get("focal_px")
    horizon = params.get("horizon_row_px")
    return camera_model(
        kind,
        width_px,
        height_px,
        None if focal is None else float(focal),
        None if horizon is None else float(horizon),
    )


def rays_from_pixels(camera: CameraModel, xy_px: ArrayLike) -> np.ndarray:
    """(n, 3) float64 unit rays in the robot frame of OpenCV pixel coordinates ``xy_px`` (n, 2)."""
    xy = np.asarray(xy_px, dtype=np.float64).reshape(-1, 2)
    bearing = bearing_rad_from_column(xy[:, 0], camera.width_px)
    return rays_from_angles(bearing, camera.elevation_rad(xy[:, 1]))


def pixels_from_rays(camera: CameraModel, rays: ArrayLike) -> np.ndarray:
    """(n, 2) OpenCV pixel coordinates at which the robot-frame rays (n, 3) are imaged (columns
    in [0, W)); the inverse of :func:`rays_from_pixels`."""
    r = np.asarray(rays, dtype=np.float64).reshape(-1, 3)
    bearing = np.arctan2(r[:, 1], r[:, 0])
    elevation = np.arctan2(r[:, 2], np.hypot(r[:, 0], r[:, 1]))
    x = column_from_bearing(bearing, camera.width_px)
    return np.column_stack([x, camera.row_px(elevation)])


def rays_from_keypoints(
    keypoints_xy: ArrayLike, bearings_rad: ArrayLike, camera: CameraModel
) -> np.ndarray:
    """(n, 3) unit rays (robot frame, REP-103) of keypoints from their stored bearings (rad)
    and, through ``camera``, the elevation of their rows (``keypoints_xy`` in px); (0, 3) for
    none. The rays the essential-matrix verification consumes."""
    xy = np.asarray(keypoints_xy, dtype=np.float64).reshape(-1, 2)
    return rays_from_angles(bearings_rad, camera.elevation_rad(xy[:, 1]))
