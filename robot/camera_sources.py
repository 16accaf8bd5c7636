"""Camera *sources*: where a robot's panoramas come from (the camera *models*, pixel <-> ray, are
:mod:`localizer.cameras`). Each source is a :class:`~localizer.robot_protocol.Camera`.

``--source`` text (:func:`open_source`):

- ``sim``: the simulated robot's renderer (``robot.sim_robot.SimulatedRobot.capture``).
- ``uvc:N`` or ``uvc:VIDEO``: a 360° camera in webcam mode (Ricoh Theta, Insta360) through
  OpenCV ``VideoCapture`` (device index N, or a video file, played in a loop). Frames are
  equirectangular and pass through as they come (these cameras put their forward direction in
  the image centre, so the robot's heading is 180° from column 0). ``,layout=dual-fisheye``:
  frames are two fisheye circles side by side (front lens left), converted to an
  equirectangular image with the front lens at column 0 (an ideal equidistant lens of
  ``,fov_deg=190``; a real camera's calibration is not applied). ``,timeout_s=5``: a read that
  takes longer is an error.
- ``files:DIR``: the next image of a folder (sorted names, regular image files only), starting
  over after the last one.
- ``ptu:DIR[,step_deg=S][,focal_px=F | ,hfov_deg=H]``: the N photos of one sweep of a pan-tilt
  unit in DIR (sorted names, photo k taken ``k * S`` degrees clockwise of photo 0; ``S``
  defaults to 360/N, ``F`` to the focal length of a ``H``-degree field of view, 60° by
  default), stitched to a cylinder (:mod:`robot.pan_stitching`, thesis §5.2) at each capture;
  the stitch is kept while the folder's files do not change. Driving the PTU is not done here.
- ``omni:CX,CY,R0,R1[:SOURCE]``: a mirror camera, unwrapped around the mirror centre (CX, CY)
  between radii R0 and R1 (pixels, :func:`localizer.panorama_io.unwrap_omni`); SOURCE a device
  index (default 0), a video file or a still image file.

Every capture is a uint8 image (grey or BGR), its wall-clock stamp and the source text. Errors
are one-line ``CameraError`` (a ``ValueError``) naming the source.
"""

from __future__ import annotations

import concurrent.futures
import math
import stat
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from localizer.cameras import MirrorUnwrap, parse_camera
from localizer.panorama_io import MAX_IMAGE_PIXELS, PanoramaError, read_grey_image, unwrap_omni
from localizer.robot_protocol import Camera, Capture, Robot
from robot.pan_stitching import focal_from_hfov_px, stitch_cylinder

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")
READ_TIMEOUT_S = 5.0
SOURCE_KINDS = ("sim", "uvc", "files", "ptu", "omni")


class CameraError(ValueError):
    """A camera source could not be opened or read; the message names the source."""


class RobotCamera:
    """The camera of a robot that captures itself (``sim``)."""

    def __init__(self, robot: Robot) -> None:
        self.robot = robot

    def capture(self) -> Capture:
        return self.robot.capture()

    def close(self) -> None:
        """Nothing to release."""


def _regular_file(path: Path, where: str) -> Path:
    """``path`` if it is a regular file (a FIFO would block OpenCV), else CameraError."""
    try:
        mode = path.stat().st_mode
    except OSError as error:
        raise CameraError(f"{where}: cannot open {path} ({error.strerror or error})") from None
    if not stat.S_ISREG(mode):
        raise CameraError(f"{where}: {path} is not a regular file")
    return path


class VideoReader:
    """Frames of an OpenCV ``VideoCapture`` (device index or video file), each read within
    ``timeout_s`` on a thread of its own; a video file starts over at its end."""

    def __init__(self, device: int | Path, where: str, timeout_s: float = READ_TIMEOUT_S) -> None:
        self.where = where
        self.timeout_s = timeout_s
        self.is_file = isinstance(device, Path)
        target = str(_regular_file(device, where)) if isinstance(device, Path) else device
        self._video = cv2.VideoCapture(target)
        if not self._video.isOpened():
            self._video.release()
            raise CameraError(f"{where}: OpenCV cannot open {target!r} as a video device or file")
        self._pending: concurrent.futures.Future[tuple[bool, np.ndarray | None]] | None = None

    def _read(self) -> tuple[bool, np.ndarray | None]:
        ok, frame = self._video.read()
        if not ok and self.is_file:  # the end of a video file: loop
            self._video.set(cv2.CAP_PROP_POS_FRAMES, 0)
            ok, frame = self._video.read()
        return ok, frame

    def _read_into(self, result: concurrent.futures.Future[tuple[bool, np.ndarray | None]]) -> None:
        try:
            result.set_result(self._read())
        except Exception as error:  # handed to the waiting read()
            result.set_exception(error)

    def read(self) -> np.ndarray:
        """The next frame (uint8); CameraError if reading fails or takes over ``timeout_s``."""
        if self._pending is not None and not self._pending.done():
            raise CameraError(f"{self.where}: a previous read is still stuck in the driver")
        # A daemon thread per read, not an executor: an executor's thread is joined at exit,
        # so a read stuck in the driver (camera unplugged) would keep the process from exiting.
        self._pending = concurrent.futures.Future()
        threading.Thread(target=self._read_into, args=(self._pending,), daemon=True).start()
        try:
            ok, frame = self._pending.result(timeout=self.timeout_s)
        except concurrent.futures.TimeoutError:
            raise CameraError(f"{self.where}: no frame within {self.timeout_s:g} s") from None
        if not ok or frame is None or frame.size == 0:
            raise CameraError(f"{self.where}: reading a frame failed (unplugged or at its end?)")
        if frame.dtype != np.uint8 or frame.shape[0] * frame.shape[1] > MAX_IMAGE_PIXELS:
            raise CameraError(f"{self.where}: unusable frame {frame.dtype} {frame.shape}")
        return frame

    def close(self) -> None:
        """Release the device; with a read stuck in the driver it is left to the process's end
        (releasing it under that read could crash OpenCV)."""
        if self._pending is None or self._pending.done():
            self._video.release()


def dual_fisheye_maps(size_px: tuple[int, int], fov_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """``cv2.remap`` maps from a dual-fisheye frame ``(width, height)`` (two equidistant circles
    of ``fov_deg``, side by side, each ``height`` across; the front lens left) to an
    equirectangular image of the same size, the front lens's axis at column 0."""
    w, h = size_px
    col, row = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    azimuth = -2.0 * np.pi * col / w  # toploc's convention: columns clockwise
    elevation = np.pi * ((h - 1) / 2.0 - row) / h
    x = np.cos(elevation) * np.cos(azimuth)  # robot frame: x forward, y left, z up
    y = np.cos(elevation) * np.sin(azimuth)
    z = np.sin(elevation)
    front = x >= 0
    theta = np.arccos(np.clip(np.where(front, x, -x), -1.0, 1.0))  # angle from the lens axis
    radius = (h / 2.0) * theta / (math.radians(fov_deg) / 2.0)
    side = np.hypot(y, z)
    side = np.where(side > 1e-12, side, 1.0)
    right = np.where(front, -y, y) / side  # image right: the robot's right (front), left (back)
    down = -z / side
    centre_x = np.where(front, (w / 2.0 - 1) / 2.0, w / 2.0 + (w / 2.0 - 1) / 2.0)
    map_x = centre_x + radius * right
    map_y = (h - 1) / 2.0 + radius * down
    return map_x.astype(np.float32), map_y.astype(np.float32)


class UvcCamera:
    """A 360° camera through OpenCV ``VideoCapture`` (see the module docstring)."""

    def __init__(
        self,
        device: int | Path,
        layout: str = "equirect",
        fov_deg: float = 190.0,
        timeout_s: float = READ_TIMEOUT_S,
    ) -> None:
        self.name = f"uvc:{device}"
        if layout not in ("equirect", "dual-fisheye"):
            raise CameraError(f"{self.name}: layout must be equirect or dual-fisheye, got {layout}")
        if not 180.0 <= fov_deg < 360.0:
            raise CameraError(f"{self.name}: fov_deg must be in [180, 360), got {fov_deg:g}")
        self.layout = layout
        self.fov_deg = fov_deg
        self._maps: tuple[tuple[int, int], tuple[np.ndarray, np.ndarray]] | None = None
        self._video = VideoReader(device, self.name, timeout_s)

    def capture(self) -> Capture:
        frame = self._video.read()
        h, w = frame.shape[:2]
        if abs(w / h - 2.0) > 0.02:
            raise CameraError(
                f"{self.name}: frame is {w}x{h} px, not 2:1 (equirectangular or dual-fisheye)"
            )
        if self.layout == "dual-fisheye":
            if self._maps is None or self._maps[0] != (w, h):
                self._maps = ((w, h), dual_fisheye_maps((w, h), self.fov_deg))
            map_x, map_y = self._maps[1]
            frame = cv2.remap(frame, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        return Capture(frame, time.time(), self.name)

    def close(self) -> None:
        self._video.close()


def _is_regular(path: Path) -> bool:
    """Whether ``path`` is a regular file now (a dangling symlink or a vanished file is not)."""
    try:
        return stat.S_ISREG(path.stat().st_mode)
    except OSError:
        return False


def image_files(folder: Path, where: str) -> list[Path]:
    """The regular image files of ``folder`` by name (no sub-folders, FIFOs or other files)."""
    if not folder.is_dir():
        raise CameraError(f"{where}: {folder} is not a folder")
    files = sorted(
        p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and _is_regular(p)
    )
    if not files:
        raise CameraError(f"{where}: {folder} has no image files ({', '.join(IMAGE_SUFFIXES)})")
    return files


class FilesCamera:
    """The images of a folder in name order, one per capture, starting over after the last;
    read with :func:`localizer.panorama_io.read_grey_image` (grey, size bounded)."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.name = f"files:{folder}"
        self.files = image_files(folder, self.name)
        self._next = 0

    def capture(self) -> Capture:
        path = self.files[self._next]
        self._next = (self._next + 1) % len(self.files)
        try:
            image = read_grey_image(path)
        except PanoramaError as error:
            raise CameraError(f"{self.name}: {error}") from None
        return Capture(image, time.time(), f"files:{path.name}")

    def close(self) -> None:
        """Nothing to release."""


class PtuCamera:
    """The photos of one pan-tilt sweep in a folder, stitched to a cylinder (module docstring)."""

    def __init__(
        self,
        folder: Path,
        step_deg: float | None = None,
        focal_px: float | None = None,
        hfov_deg: float = 60.0,
    ) -> None:
        self.folder = folder
        self.name = f"ptu:{folder}"
        self.step_deg = step_deg
        self.focal_px = focal_px
        self.hfov_deg = hfov_deg
        image_files(folder, self.name)  # fail at once on an empty folder
        self._cache: tuple[object, np.ndarray] | None = None

    def capture(self) -> Capture:
        files = image_files(self.folder, self.name)
        try:
            key = [(p.name, p.stat().st_mtime_ns, p.stat().st_size) for p in files]
        except OSError as error:  # a photo removed while we looked
            raise CameraError(f"{self.name}: {error.filename}: {error.strerror}") from None
        if self._cache is None or self._cache[0] != key:
            self._cache = (key, self._stitch(files))
        return Capture(self._cache[1], time.time(), self.name)

    def _stitch(self, files: list[Path]) -> np.ndarray:
        if len(files) < 2:
            raise CameraError(f"{self.name}: a sweep needs at least 2 photos, found {len(files)}")
        try:
            photos = [read_grey_image(p) for p in files]
        except PanoramaError as error:
            raise CameraError(f"{self.name}: {error}") from None
        step = self.step_deg if self.step_deg is not None else 360.0 / len(photos)
        focal = self.focal_px or focal_from_hfov_px(photos[0].shape[1], self.hfov_deg)
        try:
            return stitch_cylinder(photos, focal, step).image
        except ValueError as error:
            raise CameraError(f"{self.name}: {error}") from None

    def close(self) -> None:
        """Nothing to release."""


class OmniCamera:
    """A mirror camera: frames from a device, a video or a still image, unwrapped."""

    def __init__(self, unwrap: MirrorUnwrap, source: int | Path, name: str) -> None:
        self.unwrap = unwrap
        self.name = name
        self.still = isinstance(source, Path) and source.suffix.lower() in IMAGE_SUFFIXES
        self.path = source if isinstance(source, Path) else None
        self._video = None if self.still else VideoReader(source, name)

    def capture(self) -> Capture:
        try:
            if self._video is None:
                assert self.path is not None
                grey = read_grey_image(self.path)
            else:
                grey = cv2.cvtColor(self._video.read(), cv2.COLOR_BGR2GRAY)
            panorama = unwrap_omni(grey, self.unwrap, self.name)
        except PanoramaError as error:
            raise CameraError(str(error)) from None
        return Capture(panorama, time.time(), self.name)

    def close(self) -> None:
        if self._video is not None:
            self._video.close()


@dataclass(frozen=True)
class SourceText:
    """``KIND:ARGUMENT[,key=value]...`` split up (options only from the known keys)."""

    kind: str
    argument: str
    options: dict[str, float | str]


def split_source(text: str, keys: tuple[str, ...] = ()) -> SourceText:
    """Split ``text``; trailing ``,key=value`` parts with a key of ``keys`` are options."""
    kind, _, argument = text.strip().partition(":")
    options: dict[str, float | str] = {}
    parts = argument.split(",")
    while len(parts) > 1 and parts[-1].partition("=")[0] in keys:
        key, _, value = parts.pop().partition("=")
        try:
            options[key] = float(value)
        except ValueError:
            options[key] = value
    return SourceText(kind, ",".join(parts), options)


def _number(text: str, options: dict[str, float | str], key: str) -> float | None:
    value = options.get(key)
    if value is not None and not (isinstance(value, float) and math.isfinite(value) and value > 0):
        raise CameraError(f"source {text!r}: {key} must be a positive number, got {value!r}")
    return value if value is None else float(value)


def _device(argument: str) -> int | Path:
    return int(argument) if argument.isdigit() else Path(argument)


def open_source(text: str, robot: Robot | None = None) -> Camera:
    """Open the camera source named by ``text`` (module docstring); ``sim`` needs ``robot``.
    ``CameraError`` (one line naming the text) for a malformed text or a source that cannot
    be opened."""
    kind = text.strip().partition(":")[0]
    usage = "sim, uvc:N|VIDEO, files:DIR, ptu:DIR[,step_deg=..], omni:CX,CY,R0,R1[:SOURCE]"
    if kind not in SOURCE_KINDS:
        raise CameraError(f"source {text!r}: unknown kind; expected {usage}")
    if kind == "sim":
        if text.strip() != "sim" or robot is None:
            raise CameraError(f"source {text!r}: sim takes no argument and needs the sim robot")
        return RobotCamera(robot)
    if kind == "omni":
        _, _, rest = text.strip().partition(":")
        numbers, _, device = rest.partition(":")
        try:
            mirror = parse_camera(f"omni:{numbers}").mirror
        except ValueError as error:
            raise CameraError(f"source {text!r}: {error}") from None
        assert mirror is not None
        return OmniCamera(mirror, _device(device or "0"), f"omni:{rest}")
    parsed = split_source(
        text, ("layout", "fov_deg", "timeout_s", "step_deg", "focal_px", "hfov_deg")
    )
    if not parsed.argument:
        raise CameraError(f"source {text!r}: {kind} needs an argument; expected {usage}")
    allowed = {
        "uvc": ("layout", "fov_deg", "timeout_s"),
        "files": (),
        "ptu": ("step_deg", "focal_px", "hfov_deg"),
    }[kind]
    extra = sorted(set(parsed.options) - set(allowed))
    if extra:
        raise CameraError(f"source {text!r}: {kind} takes no option {', '.join(extra)}")
    if kind == "uvc":
        layout = str(parsed.options.get("layout", "equirect"))
        fov = _number(text, parsed.options, "fov_deg") or 190.0
        timeout = _number(text, parsed.options, "timeout_s") or READ_TIMEOUT_S
        return UvcCamera(_device(parsed.argument), layout, fov, timeout)
    if kind == "files":
        return FilesCamera(Path(parsed.argument))
    return PtuCamera(
        Path(parsed.argument),
        _number(text, parsed.options, "step_deg"),
        _number(text, parsed.options, "focal_px"),
        _number(text, parsed.options, "hfov_deg") or 60.0,
    )
