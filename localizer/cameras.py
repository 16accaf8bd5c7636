"""Which camera an image comes from, and the keypoint filters on its rows.

The camera models themselves (pixel <-> unit ray in the robot frame: :class:`~homing.cameras.
Cylinder`, :class:`~homing.cameras.Equirect`) and their one factory live in
:mod:`homing.cameras`, on the ground floor, so that a fingerprint carries its camera
(:attr:`mapdb.records.Fingerprint.camera`) and the renderer draws with the same model.

A camera is chosen per image from a :class:`CameraSpec` (``--camera auto|cylinder|equirect|
omni:CX,CY,R0,R1``) and the image's size, in one place (:func:`panorama_kind`): ``auto`` reads
a 2:1 image as equirectangular and one at least :data:`MIN_CYLINDER_ASPECT` times as wide as
high as a cylinder, and refuses any other (a 4:3 photo is no 360° panorama) unless its camera
is named. An omnidirectional mirror image (``omni``) is unwrapped into a cylinder
(:func:`localizer.panorama_io.unwrap_omni`).

Everything here is pure numpy: scalars or arrays in, float arrays (or boolean masks) out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from homing.cameras import CameraModel

RowsSelection = Literal["all", "lower", "upper"]
ROWS_SELECTIONS: tuple[str, ...] = ("all", "lower", "upper")
CAMERA_KINDS: tuple[str, ...] = ("auto", "cylinder", "equirect", "omni")
EQUIRECT_ASPECT_TOLERANCE = 0.01
"""``auto`` reads an image as equirectangular when ``|W / H - 2| <= 2 * tolerance``."""
MIN_CYLINDER_ASPECT = 2.5
"""``auto`` reads an image at least this many times as wide as high as a cylinder (toploc's
own are 1024 x 192 and 512 x 96, 5.3:1; a cylinder of square pixels spanning up to 103° of
elevation is wider than this), and refuses a narrower one that is not 2:1."""


class NotPanoramaError(ValueError):
    """An image whose size is no 360° panorama's for the camera it is read with."""


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


def panorama_kind(spec: CameraSpec, width_px: int, height_px: int, source: str = "image") -> str:
    """``"cylinder"`` or ``"equirect"``: the model of a panorama of this size under ``spec``
    (an unwrapped mirror image is a cylinder). ``auto`` refuses an image that is neither 2:1
    nor at least :data:`MIN_CYLINDER_ASPECT`:1 with a :class:`NotPanoramaError` naming
    ``source``, its size, what a 360° panorama looks like and how to name its camera; a named
    camera is taken at its word."""
    if spec.kind == "omni":
        return "cylinder"
    if spec.kind != "auto":
        return spec.kind
    if is_equirect_size(width_px, height_px):
        return "equirect"
    if width_px >= MIN_CYLINDER_ASPECT * height_px:
        return "cylinder"
    raise NotPanoramaError(
        f"{source}: {width_px}x{height_px} px ({width_px / height_px:.2f}:1) is not a 360° "
        f"panorama: an equirectangular one is 2:1 (e.g. 2048x1024), a cylindrical one at least "
        f"{MIN_CYLINDER_ASPECT:g}:1 (e.g. 1024x192); if it is one, name its camera with "
        f"--camera equirect or --camera cylinder"
    )


# --- masks on rows --------------------------------------------------------------------------------


def horizon_band_mask(y_px: ArrayLike, camera: CameraModel, band_deg: float | None) -> np.ndarray:
    """True where row coordinate ``y_px`` is within ±``band_deg`` degrees of the horizon.

    ``band_deg=None`` keeps everything. Pass ``np.arange(H)`` for a per-row mask of the image, or
    keypoint y coordinates to filter keypoints.
    """
    return rows_kept(y_px, camera, band_deg=band_deg)


def elevation_mask(
    y_px: ArrayLike,
    camera: CameraModel,
    min_elevation_deg: float | None,
    max_elevation_deg: float | None,
) -> np.ndarray:
    """True where row coordinate ``y_px`` is seen between the two elevations (degrees; ``None``:
    no limit on that side). This leaves out the nadir (tripod, robot body) and the zenith
    (ceiling lamps) of a spherical panorama."""
    return rows_kept(
        y_px, camera, min_elevation_deg=min_elevation_deg, max_elevation_deg=max_elevation_deg
    )


def rows_mask(y_px: ArrayLike, camera: CameraModel, rows: RowsSelection) -> np.ndarray:
    """True where row coordinate ``y_px`` lies in the selected half of the panorama.

    ``"lower"`` is at or below the horizon row (``y >= h``; closer objects, thesis §5.9),
    ``"upper"`` strictly above it (``y < h``), so the two halves partition the image;
    ``"all"`` keeps everything.
    """
    return rows_kept(y_px, camera, rows=rows)


def rows_kept(
    y_px: ArrayLike,
    camera: CameraModel,
    band_deg: float | None = None,
    min_elevation_deg: float | None = None,
    max_elevation_deg: float | None = None,
    rows: str = "all",
) -> np.ndarray:
    """True where row coordinate ``y_px`` passes every filter at once: the horizon band of
    ±``band_deg`` degrees, the elevations between ``min_elevation_deg`` and
    ``max_elevation_deg`` (degrees; None: no limit) and the ``rows`` half (see
    :func:`horizon_band_mask`, :func:`elevation_mask`, :func:`rows_mask`)."""
    if rows not in ROWS_SELECTIONS:
        raise ValueError(f"rows must be one of {ROWS_SELECTIONS}, got {rows!r}")
    if band_deg is not None and not (np.isfinite(band_deg) and 0.0 <= band_deg < 90.0):
        raise ValueError(f"band_deg must be in [0, 90), got {band_deg!r}")
    y = np.asarray(y_px, dtype=float)
    keep = np.ones(y.shape, dtype=bool)
    if band_deg is not None or min_elevation_deg is not None or max_elevation_deg is not None:
        elevation_rad = camera.elevation_rad(y)
        elevation_deg = np.rad2deg(elevation_rad)
        if band_deg is not None:
            # A hair of slack so a row lying exactly on the band edge is kept despite rounding.
            keep &= np.abs(elevation_rad) <= np.deg2rad(band_deg) + 1e-12
        if min_elevation_deg is not None:
            keep &= elevation_deg >= min_elevation_deg
        if max_elevation_deg is not None:
            keep &= elevation_deg <= max_elevation_deg
    if rows == "lower":
        keep &= y >= camera.horizon_px
    elif rows == "upper":
        keep &= y < camera.horizon_px
    return keep
