"""Read panoramas from disk: cylindrical images, and omnidirectional mirror images unwrapped.

This is the I/O adapter of the localizer. Every image it returns is a 2-D ``uint8`` grey array in
the panorama convention of :mod:`homing.bearings` (column 0 along the heading, columns
increasing clockwise). Bad input raises :class:`PanoramaError` naming the file and the problem;
files are checked before OpenCV sees them, so no crash comes from deep inside OpenCV.

Mirror orientation assumed by :func:`unwrap_omni` (the usual catadioptric rig, e.g. Vardy's
database): the camera sits below a convex mirror of revolution and looks up at it, and the robot's
heading points towards the image direction ``heading_image_deg`` (measured counter-clockwise *on
screen* from the image's +x axis; 90 = straight up in the image). Seen from below, the world is
mirrored: the robot's left (azimuth +90°) appears 90° clockwise on screen from the heading. The
outer rim of the mirror sees the highest elevations, so it becomes the top row. If the camera
looks down onto the mirror, or the image was flipped left-right, pass ``flip=True``; if the
mirror's rim sees downwards, pass ``outer_at_top=False``.
"""

from __future__ import annotations

import io
import math
import stat
import warnings
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from localizer.cameras import MirrorUnwrap

MIN_SIDE_PX = 2
"""Smallest accepted image side in pixels (a one-pixel-wide image is not a panorama)."""

MAX_IMAGE_PIXELS = 75_000_000
"""Largest accepted image, width x height, checked in the file's header before decoding. It
admits the largest consumer 360° photos (Insta360 X4: 11968 x 5984, 72 MP); decoding one takes
about 3 bytes per pixel."""

MAX_FILE_BYTES = 512 * 1024 * 1024
"""Largest accepted image file (bytes), checked before reading it."""

_MAGIC: tuple[tuple[bytes, str], ...] = (
    (b"\x89PNG\r\n\x1a\n", "PNG"),
    (b"\xff\xd8\xff", "JPEG"),
    (b"BM", "BMP"),
    (b"II*\x00", "TIFF"),
    (b"MM\x00*", "TIFF"),
    (b"P5", "PGM"),
    (b"P6", "PPM"),
)


class PanoramaError(ValueError):
    """A panorama could not be read or unwrapped; the message names the file and the reason."""


class ImageTooLargeError(PanoramaError):
    """An image's header says it has more pixels than accepted."""


def _sniff_format(head: bytes) -> str | None:
    """Image format named by the file's leading magic bytes, or None if unrecognised."""
    if head[:4] == b"RIFF" and head[8:12] == b"WEBP":
        return "WebP"
    for magic, name in _MAGIC:
        if head.startswith(magic):
            return name
    return None


def _read_bytes(path: Path) -> bytes:
    """The bytes of ``path``, which must be a regular file (a FIFO or ``/dev/zero`` would never
    end) of at most ``MAX_FILE_BYTES``."""
    try:
        status = path.stat()
    except FileNotFoundError:
        raise PanoramaError(f"{path}: no such file") from None
    except OSError as exc:
        raise PanoramaError(f"{path}: cannot read file ({exc.strerror or exc})") from exc
    if stat.S_ISDIR(status.st_mode):
        raise PanoramaError(f"{path}: is a directory, not an image file")
    if not stat.S_ISREG(status.st_mode):
        raise PanoramaError(f"{path}: not a regular file (a device, FIFO or socket)")
    if status.st_size > MAX_FILE_BYTES:
        raise PanoramaError(
            f"{path}: file is {status.st_size} bytes; at most {MAX_FILE_BYTES} are read"
        )
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise PanoramaError(f"{path}: cannot read file ({exc.strerror or exc})") from exc
    if not data:
        raise PanoramaError(f"{path}: file is empty (0 bytes)")
    return data


def _check_size(image: np.ndarray, source: str) -> None:
    if image.ndim != 2:
        raise PanoramaError(f"{source}: expected a 2-D grey image, got shape {image.shape}")
    h, w = image.shape
    if h < MIN_SIDE_PX or w < MIN_SIDE_PX:
        raise PanoramaError(
            f"{source}: image is {w}x{h} px (width x height); "
            f"at least {MIN_SIDE_PX}x{MIN_SIDE_PX} is needed"
        )


def header_size_px(data: bytes) -> tuple[int, int] | None:
    """``(width, height)`` of the encoded image ``data`` from its header, without decoding the
    pixels (Pillow reads only the header); None if Pillow does not know the format.

    Raises ``PIL.Image.DecompressionBombError`` past Pillow's own limit (about 179 MP)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        try:
            with Image.open(io.BytesIO(data)) as image:
                return image.size
        except (OSError, ValueError, SyntaxError):
            return None


def check_image_header(data: bytes, source: str, max_pixels: int = MAX_IMAGE_PIXELS) -> None:
    """Raise PanoramaError naming ``source`` if the header of ``data`` says the image has more
    than ``max_pixels`` pixels (width x height), or its size cannot be read from the header,
    before anything decodes it."""
    limit = f"at most {max_pixels} pixels are accepted (shrink it first)"
    try:
        size = header_size_px(data)
    except Image.DecompressionBombError as error:
        raise ImageTooLargeError(f"{source}: {error.args[0].split(',')[0]}; {limit}") from None
    if size is None:  # OpenCV would decode it unbounded (e.g. Radiance .hdr, .pfm): refused
        fmt = _sniff_format(data[:16])
        if fmt is None:
            raise PanoramaError(
                f"{source}: not an image (content is not a recognised image format, "
                f"{len(data)} bytes; PNG, JPEG, TIFF, BMP, WebP and PNM are read)"
            )
        raise PanoramaError(f"{source}: corrupt or truncated {fmt} file ({len(data)} bytes)")
    if size[0] * size[1] > max_pixels:
        raise ImageTooLargeError(f"{source}: image is {size[0]}x{size[1]} px; {limit}")


def decode_grey(data: bytes, source: str, max_pixels: int = MAX_IMAGE_PIXELS) -> np.ndarray:
    """Decode an encoded image (PNG, JPEG, ...; grey, colour or 16-bit) to a 2-D ``uint8`` grey
    array; PanoramaError naming ``source`` if it is too large, not an image, truncated, corrupt,
    or smaller than ``MIN_SIDE_PX`` on a side."""
    check_image_header(data, source, max_pixels)
    try:
        image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_GRAYSCALE)
    except (cv2.error, MemoryError) as error:
        reason = str(error).strip().splitlines()[-1] if str(error).strip() else "out of memory"
        raise PanoramaError(f"{source}: cannot decode the image ({reason})") from None
    if image is None:
        fmt = _sniff_format(data[:16])
        if fmt is None:
            raise PanoramaError(
                f"{source}: not an image (content is not a recognised image format, "
                f"{len(data)} bytes)"
            )
        raise PanoramaError(f"{source}: corrupt or truncated {fmt} file ({len(data)} bytes)")
    _check_size(image, source)
    return image


def read_grey_image(path: str | Path, max_pixels: int = MAX_IMAGE_PIXELS) -> np.ndarray:
    """Read any image file (PNG, JPEG, ...; grey, colour or 16-bit) as a 2-D ``uint8`` grey array.

    Raises PanoramaError for a missing, empty, unreadable, truncated or corrupt file, a file that
    is not a regular file or not an image, an image larger than ``max_pixels`` (read from its
    header, before decoding), and an image smaller than ``MIN_SIDE_PX`` on a side.
    """
    path = Path(path)
    return decode_grey(_read_bytes(path), str(path), max_pixels)


def read_panorama(path: str | Path) -> np.ndarray:
    """Read a 360° camera image as grey uint8: a cylinder or an equirectangular sphere (column 0
    along the heading, clockwise), or a mirror image that the extraction unwraps
    (:func:`localizer.features.extract_with_camera`)."""
    return read_grey_image(path)


def _check_unwrap(image_shape: tuple[int, ...], unwrap: MirrorUnwrap, source: str) -> None:
    """Raise PanoramaError unless the annulus and output width fit the mirror image."""
    h, w = image_shape[:2]
    cx, cy = unwrap.centre_x_px, unwrap.centre_y_px
    r_in, r_out = unwrap.inner_radius_px, unwrap.outer_radius_px
    values = (cx, cy, r_in, r_out, unwrap.heading_image_deg)
    if not all(math.isfinite(float(v)) for v in values):
        raise PanoramaError(f"{source}: unwrap parameters must be finite, got {unwrap}")
    if not (-0.5 <= cx <= w - 0.5 and -0.5 <= cy <= h - 0.5):
        raise PanoramaError(
            f"{source}: mirror centre ({cx}, {cy}) px lies outside the {w}x{h} image"
        )
    if r_in < 0 or r_out - r_in < MIN_SIDE_PX:
        raise PanoramaError(
            f"{source}: unwrap radii out of range: need 0 <= inner < outer with at least "
            f"{MIN_SIDE_PX} px between them, got inner={r_in}, outer={r_out}"
        )
    fits_px = min(cx + 0.5, w - 0.5 - cx, cy + 0.5, h - 0.5 - cy)
    if r_out > fits_px + 1e-9:
        raise PanoramaError(
            f"{source}: unwrap radii out of range: outer radius {r_out} px reaches outside the "
            f"{w}x{h} image around centre ({cx}, {cy}); at most {fits_px} px fits"
        )
    if unwrap.width_px is not None and (
        int(unwrap.width_px) != unwrap.width_px or unwrap.width_px < MIN_SIDE_PX
    ):
        raise PanoramaError(
            f"{source}: output width must be an integer >= {MIN_SIDE_PX}, got {unwrap.width_px!r}"
        )


def _roll_rows_fractional(polar: np.ndarray, index: np.ndarray) -> np.ndarray:
    """Rows of ``polar`` sampled at fractional, periodic row positions ``index`` (linear)."""
    n = polar.shape[0]
    i0 = np.floor(index).astype(int)
    t = (index - i0)[:, None]
    lo = polar[np.mod(i0, n)].astype(np.float32)
    hi = polar[np.mod(i0 + 1, n)].astype(np.float32)
    return (1.0 - t) * lo + t * hi


def unwrap_omni(image: np.ndarray, unwrap: MirrorUnwrap, source: str = "<array>") -> np.ndarray:
    """Unwrap a grey ``uint8`` mirror image into a cylindrical panorama with ``cv2.warpPolar``.

    Returns ``(floor(outer) - ceil(inner) + 1)`` rows (radius decreasing downwards when
    ``outer_at_top``) by ``unwrap.panorama_width_px`` columns, column 0 along the heading,
    columns clockwise. ``source`` names the image in error messages.
    """
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise PanoramaError(f"{source}: expected a uint8 image, got dtype {image.dtype}")
    _check_size(image, source)
    _check_unwrap(image.shape, unwrap, source)
    width = unwrap.panorama_width_px
    if width < MIN_SIDE_PX:
        raise PanoramaError(f"{source}: unwrapped width {width} px is too small")
    # warpPolar: output row i is the pixel-frame angle atan2(dy, dx) = 2*pi*i/width (y down), and
    # output column j is the radius j * max_radius / n_radii; n_radii = max_radius gives 1 px.
    n_radii = math.floor(unwrap.outer_radius_px) + 1
    polar = cv2.warpPolar(
        image,
        (n_radii, width),
        (float(unwrap.centre_x_px), float(unwrap.centre_y_px)),
        float(n_radii),
        cv2.INTER_LINEAR | cv2.WARP_POLAR_LINEAR,
    )
    # Panorama column c looks along azimuth phi = -2*pi*c/W. On screen (CCW from +x) that is
    # a = h - phi (mirrored view from below) or a = h + phi (flip); pixel angle = -a.
    c = np.arange(width, dtype=float)
    h_rows = unwrap.heading_image_deg / 360.0 * width
    index = (c - h_rows) if unwrap.flip else (-c - h_rows)
    columns = _roll_rows_fractional(polar, np.mod(index, width))  # (width, n_radii)
    r_first = math.ceil(unwrap.inner_radius_px)
    panorama = columns[:, r_first:n_radii].T  # rows: radius increasing downwards
    if unwrap.outer_at_top:
        panorama = panorama[::-1]
    return np.ascontiguousarray(np.clip(np.rint(panorama), 0, 255).astype(np.uint8))


def read_omni_panorama(path: str | Path, unwrap: MirrorUnwrap) -> np.ndarray:
    """Read an omnidirectional mirror image and unwrap it (see :func:`unwrap_omni`)."""
    return unwrap_omni(read_grey_image(path), unwrap, source=str(Path(path)))
