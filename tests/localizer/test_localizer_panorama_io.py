"""Reading panoramas from disk, unwrapping mirror images, and clear errors for bad input."""

from __future__ import annotations

import re
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from localizer.cameras import MirrorUnwrap
from localizer.panorama_io import (
    PanoramaError,
    read_grey_image,
    read_omni_panorama,
    read_panorama,
    unwrap_omni,
)


def _png_bytes(image: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", image)
    assert ok
    return buf.tobytes()


def _zero_size_png() -> bytes:
    """A syntactically framed PNG whose header claims 0 x 0 pixels."""

    def chunk(kind: bytes, body: bytes) -> bytes:
        crc = zlib.crc32(kind + body) & 0xFFFFFFFF
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)

    ihdr = struct.pack(">IIBBBBB", 0, 0, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(b""))
        + chunk(b"IEND", b"")
    )


def test_read_grey_png_round_trip(tmp_path: Path, textured: np.ndarray) -> None:
    path = tmp_path / "pano.png"
    cv2.imwrite(str(path), textured)
    image = read_panorama(path)
    assert image.dtype == np.uint8 and image.shape == textured.shape
    np.testing.assert_array_equal(image, textured)


@pytest.mark.parametrize("suffix", [".png", ".jpg"])
def test_colour_becomes_grey(tmp_path: Path, textured: np.ndarray, suffix: str) -> None:
    colour = cv2.merge([textured, textured // 2, 255 - textured])
    path = tmp_path / f"colour{suffix}"
    cv2.imwrite(str(path), colour)
    image = read_panorama(str(path))
    assert image.ndim == 2 and image.dtype == np.uint8 and image.shape == textured.shape


def _write_bad(tmp_path: Path, case: str, textured: np.ndarray) -> Path:
    png = _png_bytes(textured)
    _, jpg = cv2.imencode(".jpg", textured)
    contents = {
        "empty.png": b"",
        "truncated.png": png[: len(png) // 2],
        "truncated.jpg": jpg.tobytes()[: len(jpg) // 2],
        "notes.png": b"this is a text file, not a picture\n" * 4,
        "one_pixel.png": _png_bytes(np.zeros((1, 1), np.uint8)),
        "one_row.png": _png_bytes(np.zeros((1, 64), np.uint8)),
        "zero_size.png": _zero_size_png(),
    }
    path = tmp_path / case
    if case == "a_directory.png":
        path.mkdir()
    elif case != "missing.png":
        path.write_bytes(contents[case])
    return path


BAD_CASES = {
    "missing.png": "no such file",
    "a_directory.png": "directory",
    "empty.png": "empty",
    "truncated.png": "corrupt or truncated PNG",
    "truncated.jpg": "corrupt or truncated JPEG",
    "notes.png": "not an image",
    "one_pixel.png": "1x1 px",
    "one_row.png": "64x1 px",
    "zero_size.png": "corrupt or truncated PNG",
}


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_bad_input_names_file_and_problem(tmp_path: Path, textured: np.ndarray, case: str) -> None:
    path = _write_bad(tmp_path, case, textured)
    with pytest.raises(PanoramaError, match=re.escape(case)) as info:
        read_grey_image(path)
    assert BAD_CASES[case] in str(info.value)
    assert isinstance(info.value, ValueError)


# --- omnidirectional mirror images --------------------------------------------------------------

CX, CY, R_IN, R_OUT, R_MARK = 110.0, 100.0, 30.0, 95.0, 70.0


def _mirror_image(azimuth_deg: float, flip: bool = False, heading_image_deg: float = 90.0):
    """A mid-grey mirror image with a bright ring and one dark marker at robot azimuth."""
    h, w = 201, 221
    yy, xx = np.mgrid[:h, :w].astype(float)
    r = np.hypot(xx - CX, yy - CY)
    image = np.full((h, w), 128.0)
    image[np.abs(r - 50.0) < 1.5] = 230.0
    # Screen angle (CCW on screen from +x) of the azimuth: mirrored view from below unless flip.
    a = np.deg2rad(heading_image_deg + (azimuth_deg if flip else -azimuth_deg))
    mx, my = CX + R_MARK * np.cos(a), CY - R_MARK * np.sin(a)
    image -= 120.0 * np.exp(-((xx - mx) ** 2 + (yy - my) ** 2) / (2 * 2.0**2))
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def _marker_position(panorama: np.ndarray) -> tuple[float, float]:
    """Circular weighted centroid (column, row) of the darkness below the background."""
    weight = np.clip(128.0 - panorama.astype(float), 0, None)
    w = panorama.shape[1]
    angles = 2 * np.pi * np.arange(w) / w
    col_w = weight.sum(axis=0)
    col = (np.angle(np.sum(col_w * np.exp(1j * angles))) % (2 * np.pi)) * w / (2 * np.pi)
    row = float((weight.sum(axis=1) * np.arange(panorama.shape[0])).sum() / weight.sum())
    return float(col), row


@pytest.mark.parametrize("azimuth_deg", [0.0, 30.0, 90.0, -90.0, 179.0, -135.5])
@pytest.mark.parametrize("flip", [False, True])
def test_unwrap_marker_lands_at_expected_column(azimuth_deg: float, flip: bool) -> None:
    unwrap = MirrorUnwrap(CX, CY, R_IN, R_OUT, width_px=360, flip=flip)
    panorama = unwrap_omni(_mirror_image(azimuth_deg, flip=flip), unwrap)
    assert panorama.dtype == np.uint8
    assert panorama.shape == (95 - 30 + 1, 360)
    col, row = _marker_position(panorama)
    expected_col = (-azimuth_deg) % 360.0  # one column per degree, clockwise
    assert abs((col - expected_col + 180.0) % 360.0 - 180.0) < 1.0
    assert row == pytest.approx(R_OUT - R_MARK, abs=1.0)  # outer rim on top


def test_unwrap_heading_offset_and_inner_at_top() -> None:
    unwrap = MirrorUnwrap(
        CX, CY, R_IN, R_OUT, width_px=720, heading_image_deg=0.0, outer_at_top=False
    )
    panorama = unwrap_omni(_mirror_image(45.0, heading_image_deg=0.0), unwrap)
    col, row = _marker_position(panorama)
    assert abs(col - 720 * (1 - 45.0 / 360.0)) < 1.5
    assert row == pytest.approx(R_MARK - R_IN, abs=1.0)


def test_read_omni_from_file_default_width(tmp_path: Path) -> None:
    path = tmp_path / "mirror.png"
    cv2.imwrite(str(path), _mirror_image(-60.0))
    unwrap = MirrorUnwrap(CX, CY, R_IN, R_OUT)
    panorama = read_omni_panorama(path, unwrap)
    assert panorama.shape[1] == unwrap.panorama_width_px == round(2 * np.pi * R_OUT)
    col, _ = _marker_position(panorama)
    assert abs(col - 60.0 / 360.0 * panorama.shape[1]) < 1.5


@pytest.mark.parametrize(
    ("unwrap", "problem"),
    [
        (MirrorUnwrap(CX, CY, 60.0, 40.0), "unwrap radii out of range"),
        (MirrorUnwrap(CX, CY, -5.0, 40.0), "unwrap radii out of range"),
        (MirrorUnwrap(CX, CY, 30.0, 31.0), "unwrap radii out of range"),
        (MirrorUnwrap(CX, CY, 30.0, 150.0), "reaches outside"),
        (MirrorUnwrap(500.0, CY, 30.0, 50.0), "outside the 221x201 image"),
        (MirrorUnwrap(CX, CY, 30.0, float("nan")), "finite"),
        (MirrorUnwrap(CX, CY, 30.0, 90.0, width_px=1), "output width"),
    ],
)
def test_bad_unwrap_names_file(tmp_path: Path, unwrap: MirrorUnwrap, problem: str) -> None:
    path = tmp_path / "mirror_bad.png"
    cv2.imwrite(str(path), _mirror_image(0.0))
    with pytest.raises(PanoramaError, match=r"mirror_bad\.png") as info:
        read_omni_panorama(path, unwrap)
    assert problem in str(info.value)


def test_unwrap_rejects_non_uint8_array() -> None:
    with pytest.raises(PanoramaError, match=r"<array>.*uint8"):
        unwrap_omni(np.zeros((50, 50), np.float32), MirrorUnwrap(25, 25, 5, 20))


def test_an_image_whose_size_the_header_does_not_give_is_refused_undecoded(tmp_path):
    """A Radiance .hdr: OpenCV decodes it, but its size cannot be checked first (issue 11)."""
    path = tmp_path / "wide.hdr"
    assert cv2.imwrite(str(path), np.ones((400, 9000, 3), np.float32))
    with pytest.raises(PanoramaError, match=r"not an image .* PNG, JPEG, TIFF, BMP, WebP and PNM"):
        read_grey_image(path, max_pixels=1000)
