"""The panorama on the bus: PNG bytes (lossless), the payload of ``camera/capture``,
``camera/panorama`` and ``map/add``. :func:`encode_png` writes one, :func:`decode_png` reads one
back with its size checked in the header before decoding, :func:`check_png` checks a received
one's size and signature without decoding it."""

from __future__ import annotations

import cv2
import numpy as np

from localizer.panorama_io import (
    MAX_IMAGE_PIXELS,
    ImageTooLargeError,
    PanoramaError,
    check_image_header,
)
from toploc.bus.errors import BusMessageError

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def encode_png(image: np.ndarray) -> bytes:
    """Lossless PNG bytes of a uint8 grey (H x W) or BGR (H x W x 3) image."""
    if image.dtype != np.uint8 or image.ndim not in (2, 3):
        raise ValueError(f"panorama must be uint8 HxW or HxWx3, got {image.dtype} {image.shape}")
    ok, buffer = cv2.imencode(".png", image)
    if not ok:
        raise ValueError(f"OpenCV could not encode a {image.shape} image as PNG")
    return buffer.tobytes()


def decode_png(key_expr: str, data: bytes, max_pixels: int = MAX_IMAGE_PIXELS) -> np.ndarray:
    """The image in PNG ``data`` received on ``key_expr``; BusMessageError if it is not one, or
    (read from its header, before decoding) has more than ``max_pixels`` pixels."""
    not_an_image = BusMessageError(
        f"{key_expr}: reply is not a decodable image ({len(data)} bytes, starts {data[:8]!r})"
    )
    try:
        check_image_header(data, key_expr, max_pixels)
    except ImageTooLargeError as error:
        raise BusMessageError(str(error)) from None
    except PanoramaError:
        raise not_an_image from None
    try:
        image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error:
        image = None
    if image is None:
        raise not_an_image
    return image


def check_png(where: str, payload: bytes | None, max_bytes: int) -> bytes:
    """The PNG bytes of a request received on ``where``, at most ``max_bytes`` long and starting
    with the PNG signature (not decoded yet); else BusMessageError saying which."""
    if not payload:
        raise BusMessageError(f"{where}: empty payload, expected a PNG panorama")
    if len(payload) > max_bytes:
        raise BusMessageError(
            f"{where}: the image is {len(payload)} bytes; at most "
            f"{max_bytes} are accepted (max_image_bytes)"
        )
    if not payload.startswith(PNG_SIGNATURE):
        raise BusMessageError(
            f"{where}: the payload is not a PNG image ({len(payload)} bytes, starts "
            f"{payload[:8]!r})"
        )
    return payload
