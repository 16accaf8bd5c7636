"""Camera models of 360° panoramas: each maps a pixel to a unit ray in the robot frame and back.

Frames and conventions (DESIGN.md, REP-103: x forward, y left, z up, angles CCW positive):
OpenCV pixel coordinates put pixel centres at integers, rows grow downwards. Every panorama is
``W`` columns for 360°: column 0 looks along the robot's heading and columns increase clockwise,
so a column ``x`` has azimuth ``-2*pi*x/W`` (:mod:`homing.bearings`, one convention for the
localizer, homing and the renderer). Elevation is positive above the horizon; the models differ
only in how rows map to elevations:

- :class:`Cylinder`: rows on a cylinder of radius ``focal_px`` around the camera,
  ``elevation = atan((horizon - y) / f)`` (the panoramas toploc renders and stitches; an
  unwrapped mirror image is read as one, see :mod:`localizer.panorama_io`).
- :class:`Equirect`: the whole sphere, ``H = W / 2`` rows for 180°, linear in elevation,
  ``elevation = pi * ((H - 1) / 2 - y) / H`` (what Ricoh Theta, Insta360 and most 360°
  cameras write).

A camera is chosen per image from a :class:`CameraSpec` (``--camera auto|cylinder|equirect|
omni:CX,CY,R0,R1``): ``auto`` reads a 2:1 image as equirectangular, anything else as a cylinder.
A fingerprint records its camera in its extraction parameters (:func:`camera_of`), so every
stored place keeps its own model and size.

Everything here is pure numpy: scalars or arrays in, float arrays (or boolean masks) out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike

from homing.bearings import bearing_rad_from_column, check_width_px, column_from_bearing
from mapdb.records import Fingerprint, ParamValue

RowsSelection = Literal["all", "lower", "upper"]
ROWS_SELECTIONS: tuple[str, ...] = ("all", "lower", "upper")
CAMERA_KINDS: tuple[str, ...] = ("auto", "cylinder", "equirect", "omni")
EQUIRECT_ASPECT_TOLERANCE = 0.01
"""``auto`` reads an image as equirectangular when ``|W / H - 2| <= 2 * tolerance``."""


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

    def elevation_rad(self, y_px: ArrayLike) -> np.ndarray:
        """Elevation (rad, positive up) of row coordinate ``y_px``: a point ``h - y`` pixels
        above the horizon row ``h`` of a cylinder of radius ``f`` is seen at ``atan((h - y)/f)``."""
        return np.arctan2(self.horizon_px - np.asarray(y_px, dtype=float), self.f_px)

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

    def elevation_rad(self, y_px: ArrayLike) -> np.ndarray:
        """Elevation (rad, positive up) of row coordinate ``y_px``: ``pi * (h - y) / H``."""
        return np.pi * (self.horizon_px - np.asarray(y_px, dtype=float)) / self.height_px

    def row_px(self, elevation_rad: ArrayLike) -> np.ndarray:
        """Row coordinate at which ``elevation_rad`` (in [-pi/2, pi/2]) is imaged."""
        return self.horizon_px - np.asarray(elevation_rad, dtype=float) * self.height_px / np.pi

    def params(self) -> dict[str, ParamValue]:
        """What a fingerprint records of this camera (see :func:`camera_from_params`)."""
        return {"camera": self.kind}


PanoramaCamera = Cylinder | Equirect


def rays_from_pixels(camera: PanoramaCamera, xy_px: ArrayLike) -> np.ndarray:
    """(n, 3) float64 unit rays in the robot frame of OpenCV pixel coordinates ``xy_px`` (n, 2)."""
    xy = np.asarray(xy_px, dtype=np.float64).reshape(-1, 2)
    bearing = bearing_rad_from_column(xy[:, 0], camera.width_px)
    return rays_from_angles(bearing, camera.elevation_rad(xy[:, 1]))


def pixels_from_rays(camera: PanoramaCamera, rays: ArrayLike) -> np.ndarray:
    """(n, 2) OpenCV pixel coordinates at which the robot-frame rays (n, 3) are imaged (columns
    in [0, W)); the inverse of :func:`rays_from_pixels`."""
    r = np.asarray(rays, dtype=np.float64).reshape(-1, 3)
    bearing = np.arctan2(r[:, 1], r[:, 0])
    elevation = np.arctan2(r[:, 2], np.hypot(r[:, 0], r[:, 1]))
    x = column_from_bearing(bearing, camera.width_px)
    return np.column_stack([x, camera.row_px(elevation)])


# --- which camera an image comes from -------------------------------------------------------------


@dataclass(frozen=True)
class MirrorUnwrap:
    """An omnidirectional mirror camera, and how to unwrap its image into a cylindrical panorama
    (:func:`localizer.panorama_io.unwrap_omni`, which checks the values against the image).

    ``centre_x_px``, ``centre_y_px``: the mirror's centre in OpenCV pixel coordinates of the
    mirror image. The annulus ``inner_radius_px <= r < outer_radius_px`` becomes the panorama,
    one row per pixel of radius. ``width_px`` is the panorama width (None: the outer
    circumference, ``round(2*pi*outer_radius_px)``). See :mod:`localizer.panorama_io`
    for ``heading_image_deg``, ``flip`` and ``outer_at_top``.
    """

    centre_x_px: float
    centre_y_px: float
    inner_radius_px: float
    outer_radius_px: float
    width_px: int | None = None
    heading_image_deg: float = 90.0
    flip: bool = False
    outer_at_top: bool = True

    @property
    def panorama_width_px(self) -> int:
        """Width of the unwrapped panorama in pixels (the default resolved)."""
        if self.width_px is not None:
            return int(self.width_px)
        return round(2.0 * math.pi * self.outer_radius_px)


@dataclass(frozen=True)
class CameraSpec:
    """What the user said about an image's camera: ``kind`` one of :data:`CAMERA_KINDS`, and
    for ``omni`` the mirror."""

    kind: str = "auto"
    mirror: MirrorUnwrap | None = None

    def __post_init__(self) -> None:
        if self.kind not in CAMERA_KINDS:
            raise ValueError(f"camera must be one of {CAMERA_KINDS}, got {self.kind!r}")
        if (self.kind == "omni") != (self.mirror is not None):
            raise ValueError("an omni camera needs its mirror (and only an omni camera has one)")

    def __str__(self) -> str:
        if self.mirror is None:
            return self.kind
        m = self.mirror
        radii = f"{m.inner_radius_px:g},{m.outer_radius_px:g}"
        return f"omni:{m.centre_x_px:g},{m.centre_y_px:g},{radii}"


def parse_camera(text: str) -> CameraSpec:
    """``"auto"``, ``"cylinder"``, ``"equirect"`` or ``"omni:CX,CY,R0,R1"`` (mirror centre and
    inner/outer radii in pixels of the mirror image) as a :class:`CameraSpec`; ``ValueError``
    naming the text and what is wrong."""
    kind, _, rest = text.strip().partition(":")
    if kind != "omni":
        if rest or kind not in CAMERA_KINDS:
            raise ValueError(
                f"camera {text!r}: expected auto, cylinder, equirect or omni:CX,CY,R0,R1"
            )
        return CameraSpec(kind)
    parts = rest.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) != 4:
        raise ValueError(
            f"camera {text!r}: omni needs four numbers CX,CY,R0,R1 (mirror centre x, y and "
            f"inner, outer radius in pixels)"
        )
    if not all(math.isfinite(v) for v in values) or not 0 <= values[2] < values[3]:
        raise ValueError(
            f"camera {text!r}: mirror centre and radii must be finite with 0 <= R0 < R1"
        )
    cx, cy, r0, r1 = values
    return CameraSpec("omni", MirrorUnwrap(cx, cy, r0, r1))


def is_equirect_size(width_px: int, height_px: int) -> bool:
    """Whether an image of this size is read as equirectangular by ``auto`` (a 2:1 image)."""
    return abs(width_px / height_px - 2.0) <= 2.0 * EQUIRECT_ASPECT_TOLERANCE


def panorama_kind(spec: CameraSpec, width_px: int, height_px: int) -> str:
    """``"cylinder"`` or ``"equirect"``: the model of a panorama of this size under ``spec``
    (an unwrapped mirror image is a cylinder)."""
    if spec.kind == "auto":
        return "equirect" if is_equirect_size(width_px, height_px) else "cylinder"
    return "cylinder" if spec.kind == "omni" else spec.kind


# --- the camera of a fingerprint ------------------------------------------------------------------


def camera_from_params(
    width_px: int, height_px: int, params: Mapping[str, ParamValue]
) -> PanoramaCamera:
    """The camera of a ``width_px`` x ``height_px`` panorama whose extraction ``params`` record
    ``camera`` (absent in maps made before cameras were recorded: a cylinder), and for a
    cylinder ``focal_px`` and ``horizon_row_px`` when known."""
    kind = params.get("camera", "cylinder")
    if kind == "equirect":
        return Equirect(int(width_px), int(height_px))
    if kind != "cylinder":
        raise ValueError(f"unknown camera {kind!r} in extraction parameters")
    focal = params.get("focal_px")
    horizon = params.get("horizon_row_px")
    return Cylinder(
        int(width_px),
        int(height_px),
        None if focal is None else float(focal),
        None if horizon is None else float(horizon),
    )


def camera_of(fingerprint: Fingerprint) -> PanoramaCamera:
    """The camera a fingerprint was extracted on (see :func:`camera_from_params`)."""
    return camera_from_params(
        fingerprint.image_width_px, fingerprint.image_height_px, fingerprint.params
    )


# --- masks on rows --------------------------------------------------------------------------------


def horizon_band_mask(
    y_px: ArrayLike, camera: PanoramaCamera, band_deg: float | None
) -> np.ndarray:
    """True where row coordinate ``y_px`` is within ±``band_deg`` degrees of the horizon.

    ``band_deg=None`` keeps everything. Pass ``np.arange(H)`` for a per-row mask of the image, or
    keypoint y coordinates to filter keypoints.
    """
    y = np.asarray(y_px, dtype=float)
    if band_deg is None:
        return np.ones(y.shape, dtype=bool)
    if not (np.isfinite(band_deg) and 0.0 <= band_deg < 90.0):
        raise ValueError(f"band_deg must be in [0, 90), got {band_deg!r}")
    # A hair of slack so a row lying exactly on the band edge is kept despite rounding.
    return np.abs(camera.elevation_rad(y)) <= np.deg2rad(band_deg) + 1e-12


def elevation_mask(
    y_px: ArrayLike,
    camera: PanoramaCamera,
    min_elevation_deg: float | None,
    max_elevation_deg: float | None,
) -> np.ndarray:
    """True where row coordinate ``y_px`` is seen between the two elevations (degrees; ``None``:
    no limit on that side). This leaves out the nadir (tripod, robot body) and the zenith
    (ceiling lamps) of a spherical panorama."""
    elevation_deg = np.rad2deg(camera.elevation_rad(y_px))
    keep = np.ones(elevation_deg.shape, dtype=bool)
    if min_elevation_deg is not None:
        keep &= elevation_deg >= min_elevation_deg
    if max_elevation_deg is not None:
        keep &= elevation_deg <= max_elevation_deg
    return keep


def rows_mask(y_px: ArrayLike, camera: PanoramaCamera, rows: RowsSelection) -> np.ndarray:
    """True where row coordinate ``y_px`` lies in the selected half of the panorama.

    ``"lower"`` is at or below the horizon row (``y >= h``; closer objects, thesis §5.9),
    ``"upper"`` strictly above it (``y < h``), so the two halves partition the image;
    ``"all"`` keeps everything.
    """
    y = np.asarray(y_px, dtype=float)
    if rows == "all":
        return np.ones(y.shape, dtype=bool)
    if rows == "lower":
        return y >= camera.horizon_px
    if rows == "upper":
        return y < camera.horizon_px
    raise ValueError(f"rows must be one of {ROWS_SELECTIONS}, got {rows!r}")
