"""A vectorised ray caster for cylindrical and equirectangular panoramas of a
:class:`~robot.scene.Scene`.

Camera model: the one of :mod:`homing.cameras` (the localizer reads the same pixels with the
same model). A panorama is ``width_px`` columns for 360°; column 0 looks along the robot
heading and columns increase clockwise, so the pixel centre at OpenCV x coordinate ``x`` has
robot-frame azimuth ``-2*pi*x/W`` (REP-103: counter-clockwise positive). Rows (pixel centres at
integers, 0 at the top) follow the model: a :class:`~homing.cameras.Cylinder` (focal length
``W / (2*pi)``, square pixels, unless a vertical field of view is given) or an
:class:`~homing.cameras.Equirect` sphere (``W = 2H``). :class:`PanoramaCamera` is that model
mounted ``height_m`` above the floor.

Ray casting. A ray has horizontal unit direction, so its parameter ``t`` is the horizontal
distance in metres. Walls and box sides (vertical quads) are intersected per column, and only the
hits up to the nearest floor-to-ceiling quad can be visible; each pixel then takes the nearest of
those whose height range it crosses. Floors, ceilings and box tops (horizontal quads) are
intersected per pixel. Texture lookup is nearest-texel on a mip level chosen from the pixel
footprint.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import cv2
import numpy as np

from homing.bearings import bearing_rad_from_column
from homing.cameras import CAMERA_MODELS, CameraModel, camera_model, focal_from_vfov_px
from localizer.robot_protocol import Pose2D
from robot.conditions import DEFAULT_CONDITION, Condition, apply_photometric
from robot.scene import Scene

Projection = Literal["cylinder", "equirect"]


@dataclass(frozen=True)
class PanoramaCamera:
    """A panorama camera ``height_m`` above the floor: the camera model (:attr:`model`, of
    :mod:`homing.cameras`) the renderer draws with, and its mounting height.

    ``projection`` names the model, ``"cylinder"`` (the default) or ``"equirect"`` (then ``W``
    must be ``2H`` and ``vfov_deg`` None). ``vfov_deg`` is the cylinder's vertical field of view
    from the top edge to the bottom edge of the image; None gives square pixels (focal length
    ``W / (2*pi)``).
    """

    width_px: int = 1024
    height_px: int = 192
    vfov_deg: float | None = None
    height_m: float = 1.0
    projection: Projection = "cylinder"

    def __post_init__(self) -> None:
        if self.width_px < 8 or self.height_px < 1:
            raise ValueError(
                f"panorama size must be >= 8 x 1, got {self.width_px}x{self.height_px}"
            )
        if self.vfov_deg is not None and not 0 < self.vfov_deg < 180:
            raise ValueError(f"vfov_deg must be in (0, 180), got {self.vfov_deg}")
        if not self.height_m > 0:
            raise ValueError(f"height_m must be positive, got {self.height_m}")
        if self.projection not in CAMERA_MODELS:
            raise ValueError(f"projection must be one of {CAMERA_MODELS}, got {self.projection!r}")
        if self.projection == "equirect" and (
            self.width_px != 2 * self.height_px or self.vfov_deg is not None
        ):
            raise ValueError(
                "an equirect panorama is W = 2H without vfov_deg, got "
                f"{self.width_px}x{self.height_px}, vfov_deg={self.vfov_deg}"
            )

    @cached_property
    def model(self) -> CameraModel:
        """The camera model of the rendered panoramas (:func:`homing.cameras.camera_model`)."""
        focal = None if self.vfov_deg is None else focal_from_vfov_px(self.height_px, self.vfov_deg)
        return camera_model(self.projection, self.width_px, self.height_px, focal)

    def azimuths_rad(self) -> np.ndarray:
        """(W,) robot-frame azimuth (rad, in (-pi, pi]) of each column: 0, then clockwise."""
        return bearing_rad_from_column(np.arange(self.width_px), self.width_px)

    def tan_elevations(self) -> np.ndarray:
        """(H,) tangent of the elevation of each row (of :attr:`model`), positive above the
        horizon."""
        return self.model.tan_elevation(np.arange(self.height_px))


@dataclass(frozen=True)
class RayHits:
    """What each pixel's ray hits. Arrays are (H, W); ``quad_index`` is -1 where nothing is hit.

    The ray of pixel (row, col) leaves ``origin_m`` along
    ``(cos(azimuth_rad[col]), sin(azimuth_rad[col]), tan_elevation[row])`` (building frame), and
    ``t_m`` is the ray parameter at the hit, i.e. the horizontal distance in metres.
    """

    quad_index: np.ndarray
    t_m: np.ndarray  # inf where nothing is hit
    origin_m: np.ndarray  # (3,) camera centre, building frame
    azimuth_rad: np.ndarray  # (W,) building-frame azimuth of each column
    tan_elevation: np.ndarray  # (H,)

    def points_m(self) -> np.ndarray:
        """(H, W, 3) building-frame hit points (nan where nothing is hit)."""
        t = np.where(self.quad_index >= 0, self.t_m, np.nan)
        h, w = t.shape
        ray = np.empty((h, w, 3))
        ray[..., 0] = np.cos(self.azimuth_rad)[None, :]
        ray[..., 1] = np.sin(self.azimuth_rad)[None, :]
        ray[..., 2] = self.tan_elevation[:, None]
        return self.origin_m + t[..., None] * ray


def _vertical_hits(
    scene: Scene, origin: np.ndarray, dirs: np.ndarray, tan_el: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Nearest wall/box-side hit per pixel: (H, W) quad index (-1: none) and t (inf: none)."""
    quads = np.flatnonzero(scene.axis < 2)
    axis = scene.axis[quads]
    d_axis = dirs[:, axis]  # (W, K) direction component normal to each plane
    d_along = dirs[:, 1 - axis]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # masked below
        t = (scene.coord_m[quads] - origin[axis]) / d_axis
    along = origin[1 - axis] + t * d_along
    ok = (d_axis * scene.normal_sign[quads] < 0) & (t > 1e-9)
    ok &= (along >= scene.lo_m[quads, 0]) & (along <= scene.hi_m[quads, 0])
    t = np.where(ok, t, np.inf)
    cut = np.where(scene.full_height[quads], t, np.inf).min(axis=1, keepdims=True)
    t[t > cut + 1e-9] = np.inf  # nothing behind a floor-to-ceiling quad is visible
    depth = max(int(np.isfinite(t).sum(axis=1).max()), 1)
    order = np.argsort(t, axis=1)[:, :depth]  # (W, M) candidate hits, nearest first
    t_sorted = np.take_along_axis(t, order, axis=1)
    q_sorted = quads[order]
    with np.errstate(invalid="ignore"):
        z = origin[2] + t_sorted[None] * tan_el[:, None, None]  # (H, W, M)
    inside = (z >= scene.lo_m[q_sorted, 1]) & (z <= scene.hi_m[q_sorted, 1])
    first = inside.argmax(axis=2)  # (H, W)
    cols = np.arange(len(dirs))[None, :]
    hit = np.take_along_axis(inside, first[..., None], axis=2)[..., 0]
    return np.where(hit, q_sorted[cols, first], -1), np.where(hit, t_sorted[cols, first], np.inf)


def _horizontal_hits(
    scene: Scene,
    origin: np.ndarray,
    dirs: np.ndarray,
    tan_el: np.ndarray,
    best_q: np.ndarray,
    best_t: np.ndarray,
) -> None:
    """Update ``best_q``/``best_t`` in place with nearer floor, ceiling and box-top hits."""
    quads = np.flatnonzero(scene.axis == 2)
    levels = {(float(scene.coord_m[q]), int(scene.normal_sign[q])) for q in quads}
    for z, normal in sorted(levels):
        if (z - origin[2]) * normal >= 0:
            continue  # the camera is behind this level's face
        rows = np.flatnonzero(tan_el * normal < 0)
        if len(rows) == 0:
            continue
        t_row = ((z - origin[2]) / tan_el[rows])[:, None]  # (R, 1)
        x = origin[0] + t_row * dirs[None, :, 0]  # (R, W)
        y = origin[1] + t_row * dirs[None, :, 1]
        q_sub, t_sub = best_q[rows], best_t[rows]
        same = quads[(scene.coord_m[quads] == z) & (scene.normal_sign[quads] == normal)]
        for q in same:
            (x0, y0), (x1, y1) = scene.lo_m[q], scene.hi_m[q]
            inside = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1) & (t_row < t_sub)
            q_sub[inside] = q
            t_sub = np.where(inside, t_row, t_sub)
        best_q[rows], best_t[rows] = q_sub, t_sub


def cast_rays(scene: Scene, pose: Pose2D, camera: PanoramaCamera) -> RayHits:
    """Cast the panorama's rays from ``pose`` (building frame) and return the nearest hits."""
    azimuth = pose.heading_rad + camera.azimuths_rad()
    dirs = np.stack([np.cos(azimuth), np.sin(azimuth)], axis=1)  # (W, 2) building frame
    origin = np.array([pose.x_m, pose.y_m, camera.height_m])
    tan_el = camera.tan_elevations()
    best_q, best_t = _vertical_hits(scene, origin, dirs, tan_el)
    _horizontal_hits(scene, origin, dirs, tan_el, best_q, best_t)
    return RayHits(best_q, best_t, origin, azimuth, tan_el)


def shade_hits(scene: Scene, hits: RayHits, camera: PanoramaCamera) -> np.ndarray:
    """(H, W, 3) float32 RGB radiance in grey levels (0..255) of the hit surfaces; 0 for misses.

    Textures are sampled nearest-texel from the mip level whose texel best matches the pixel
    footprint (grazing angles are limited to 0.2 of a head-on view), times the quad's shade.
    """
    q = hits.quad_index
    rows, cols = np.nonzero(q >= 0)
    qv = q[rows, cols]
    t = hits.t_m[rows, cols]
    tan_el = hits.tan_elevation[rows]
    ray = np.stack([np.cos(hits.azimuth_rad[cols]), np.sin(hits.azimuth_rad[cols]), tan_el], axis=1)
    rel = hits.origin_m + t[:, None] * ray - scene.uv_origin_m[qv]
    atlas = scene.atlas
    u_texel = np.einsum("ij,ij->i", rel, scene.u_axis[qv]) / scene.tile_m[qv, 0] * atlas.size_px
    v_texel = np.einsum("ij,ij->i", rel, scene.v_axis[qv]) / scene.tile_m[qv, 1] * atlas.size_px
    secant = np.sqrt(1.0 + tan_el**2)  # ray length per metre of horizontal distance
    cos_incidence = np.abs(ray[np.arange(len(qv)), scene.axis[qv]]) / secant
    footprint_m = t * secant * camera.model.pixel_rad / np.maximum(cos_incidence, 0.2)
    texel_m = scene.tile_m[qv].min(axis=1) / atlas.size_px
    level = np.floor(np.log2(np.maximum(footprint_m / texel_m, 1.0)) + 0.5).astype(np.int64)
    level = np.minimum(level, atlas.levels - 1)
    side = atlas.size_px >> level
    col = np.mod(np.floor(u_texel / (1 << level)).astype(np.int64), side)
    row = side - 1 - np.mod(np.floor(v_texel / (1 << level)).astype(np.int64), side)
    index = atlas.level_offset[scene.texture_index[qv], level] + row * side + col
    out = np.zeros((*q.shape, 3), np.float32)
    out[rows, cols] = atlas.texels[index].astype(np.float32) * scene.shade[qv][:, None]
    return out


def render_panorama(
    scene: Scene,
    pose: Pose2D,
    camera: PanoramaCamera | None = None,
    condition: Condition = DEFAULT_CONDITION,
    seed: int | Sequence[int] = 0,
    grey: bool = False,
) -> np.ndarray:
    """Render the panorama seen from ``pose`` (building frame) as uint8 RGB (H, W, 3) or grey.

    ``condition`` sets gain, gamma and sensor noise (seeded by ``seed``, an int or ints); the
    objects it adds must already be in ``scene`` (see :func:`robot.conditions.world_under`).
    Raises ``ValueError`` if the pose is outside every room.
    """
    camera = camera or PanoramaCamera()
    if scene.room_of(pose.x_m, pose.y_m) < 0:
        raise ValueError(f"pose ({pose.x_m}, {pose.y_m}) m is outside every room of the scene")
    radiance = shade_hits(scene, cast_rays(scene, pose, camera), camera)
    image = apply_photometric(radiance, condition, np.random.default_rng(seed))
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if grey else image
