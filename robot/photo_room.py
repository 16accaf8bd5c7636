"""Photo rooms: a real equirectangular 360° photo projected onto a box room, seen from elsewhere.

A :class:`PhotoRoom` is an axis-aligned box (room frame, REP-103, metres: floor ``z = 0`` at
``0 <= x <= size_x``, ``0 <= y <= size_y``, ceiling at ``height_m``) and the point the photo was
taken from, ``capture_height_m`` above the floor. The photo's column 0 looks along the room's +x
axis, and its pixels follow the equirectangular camera model (:class:`homing.cameras.Equirect`):
column ``x`` has azimuth ``-2*pi*x/W``, row ``y`` elevation ``pi * ((H - 1) / 2 - y) / H``.

Rendering from a pose (room frame) with a :class:`~robot.render.PanoramaCamera` (equirect or
cylinder, ``camera.height_m`` above the floor): each output pixel's ray, robot frame rotated by
the pose's heading into the room frame, leaves the box at a point X; the pixel takes the photo's
colour in the direction of X seen from the capture point (bilinear, wrapping around in azimuth).
Every surface is taken to lie on the box, so the geometry is approximate (furniture and the
room's real shape are flattened onto the walls, floor and ceiling), the texture real. From the
capture point itself the render is the photo.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from homing.cameras import Equirect, pixels_from_rays
from localizer.robot_protocol import Pose2D
from robot.conditions import DEFAULT_CONDITION, Condition, apply_photometric
from robot.render import PanoramaCamera

CAPTURE_HEIGHT_M = 1.4


@dataclass(frozen=True)
class PhotoRoom:
    """A box room of ``size_m`` (x, y) x ``height_m`` metres whose photo was taken at
    ``capture_m`` (x, y, room frame), ``capture_height_m`` above the floor."""

    name: str
    size_m: tuple[float, float]
    height_m: float
    capture_m: tuple[float, float]
    capture_height_m: float = CAPTURE_HEIGHT_M

    def __post_init__(self) -> None:
        if not (self.size_m[0] > 0 and self.size_m[1] > 0 and self.height_m > 0):
            raise ValueError(f"photo room {self.name!r}: size {self.size_m} x {self.height_m} m")
        if not self.contains(*self.capture_m, self.capture_height_m):
            raise ValueError(
                f"photo room {self.name!r}: capture point {self.capture_m} at "
                f"{self.capture_height_m} m is not inside the {self.size_m} x {self.height_m} m box"
            )

    def contains(self, x_m: float, y_m: float, z_m: float) -> bool:
        """Whether the room-frame point lies strictly inside the box."""
        return 0 < x_m < self.size_m[0] and 0 < y_m < self.size_m[1] and 0 < z_m < self.height_m

    @property
    def capture_point_m(self) -> np.ndarray:
        """(3,) the capture point in the room frame."""
        return np.array([*self.capture_m, self.capture_height_m], float)


def box_exit_m(room: PhotoRoom, origin_m: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Points (..., 3) where rays from ``origin_m`` (inside the box) along ``dirs`` (..., 3,
    any non-zero length) leave ``room``'s box, room frame, metres."""
    upper = np.array([*room.size_m, room.height_m])
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = np.where(dirs > 0, upper, 0.0)
        t_axis = np.where(dirs != 0, (bound - origin_m) / dirs, np.inf)
    t = t_axis.min(axis=-1, keepdims=True)
    return origin_m + t * dirs


def pixel_rays(camera: PanoramaCamera, heading_rad: float) -> np.ndarray:
    """(H, W, 3) room-frame ray directions of the camera's pixels at ``heading_rad`` (CCW from
    +x); each ray has unit horizontal length and vertical component ``tan(elevation)``."""
    azimuth = heading_rad + camera.azimuths_rad()
    tan_el = camera.tan_elevations()
    rays = np.empty((camera.height_px, camera.width_px, 3))
    rays[..., 0] = np.cos(azimuth)[None, :]
    rays[..., 1] = np.sin(azimuth)[None, :]
    rays[..., 2] = tan_el[:, None]
    return rays


def photo_pixel_of(
    room: PhotoRoom, points_m: np.ndarray, photo_size_px: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV pixel coordinates (x in [0, W), y) in the (W, H) photo of room-frame points
    (..., 3): the direction from the capture point to each point."""
    width_px, height_px = photo_size_px
    v = points_m - room.capture_point_m
    xy = pixels_from_rays(Equirect(width_px, height_px), v).reshape(*v.shape[:-1], 2)
    return xy[..., 0], xy[..., 1]


def _check_photo(photo: np.ndarray) -> None:
    if photo.ndim != 3 or photo.shape[2] != 3 or photo.shape[1] != 2 * photo.shape[0]:
        raise ValueError(f"photo must be an equirectangular (H, 2H, 3) array, got {photo.shape}")


def render_photo_room(
    photo: np.ndarray,
    room: PhotoRoom,
    pose: Pose2D,
    camera: PanoramaCamera,
    condition: Condition = DEFAULT_CONDITION,
    seed: int | Sequence[int] = 0,
    grey: bool = False,
) -> np.ndarray:
    """The (H, W, 3) uint8 RGB (or (H, W) grey) panorama of ``room`` seen from ``pose`` (room
    frame, metres and radians) by ``camera``, ``camera.height_m`` above the floor.

    ``photo`` is the room's equirectangular (H, 2H, 3) RGB uint8 photo; it is first area-averaged
    down to the output width if that is smaller. ``condition`` applies gain, gamma and noise
    (seeded by ``seed``); it adds no objects. ``ValueError`` if the pose is outside the box.
    """
    _check_photo(photo)
    if not room.contains(pose.x_m, pose.y_m, camera.height_m):
        raise ValueError(
            f"pose ({pose.x_m}, {pose.y_m}) m at {camera.height_m} m is outside photo room "
            f"{room.name!r} ({room.size_m} x {room.height_m} m)"
        )
    if camera.width_px < photo.shape[1]:
        size = (camera.width_px, max(camera.width_px // 2, 1))
        photo = cv2.resize(photo, size, interpolation=cv2.INTER_AREA)
    height_px, width_px = photo.shape[:2]
    origin = np.array([pose.x_m, pose.y_m, camera.height_m])
    points = box_exit_m(room, origin, pixel_rays(camera, pose.heading_rad))
    map_x, map_y = photo_pixel_of(room, points, (width_px, height_px))
    # One wrapped column each side, so bilinear lookups across column 0 / W - 1 are exact.
    padded = np.concatenate([photo[:, -1:], photo, photo[:, :1]], axis=1)
    image = cv2.remap(
        padded,
        (map_x + 1.0).astype(np.float32),
        map_y.astype(np.float32),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    )
    image = apply_photometric(image.astype(np.float32), condition, np.random.default_rng(seed))
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if grey else image
