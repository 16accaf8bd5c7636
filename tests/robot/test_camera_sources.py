"""Camera sources: a 360° webcam read through OpenCV (a video file OpenCV writes), a folder of
images, a pan-tilt sweep stitched, a real mirror image unwrapped, and the ``--source`` text."""

from __future__ import annotations

import math
import os
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest

from localizer.robot_protocol import Capture
from robot.camera_sources import (
    CameraError,
    FilesCamera,
    UvcCamera,
    VideoReader,
    dual_fisheye_maps,
    image_files,
    open_source,
)
from robot.pan_stitching import view_from_equirect

REPO = Path(__file__).resolve().parents[2]
PHOTO = REPO / "robot" / "data" / "photos" / "autoshop_01_1k.jpg"
OMNI = Path("/work/shared/realdata/omni/office_mirror.jpg")
# calib_results.txt: centre (row 545.87, col 674.32) of the image cropped by 300 px on the left;
# the ring is usable from 235 px, and 533 px is as far as the 1080-row image reaches.
OMNI_CENTRE = (674.32 + 300.0, 545.87)
OMNI_SOURCE = f"omni:{OMNI_CENTRE[0]},{OMNI_CENTRE[1]},235,533:{OMNI}"


def write_video(path: Path, frames: list[np.ndarray], fps: float = 5.0) -> Path:
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter.fourcc(*"MJPG"), fps, (w, h))
    assert writer.isOpened()
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path


def level_frames(n: int, size: tuple[int, int] = (128, 64)) -> list[np.ndarray]:
    """Frames of uniform grey levels 40, 80, ... (MJPG keeps a flat frame's level)."""
    w, h = size
    return [np.full((h, w, 3), 40 * (i + 1), np.uint8) for i in range(n)]


def test_uvc_reads_a_video_file_in_order_and_loops(tmp_path: Path) -> None:
    video = write_video(tmp_path / "theta.avi", level_frames(3))
    camera = open_source(f"uvc:{video}")
    try:
        levels = []
        for _ in range(5):
            capture = camera.capture()
            assert isinstance(capture, Capture) and capture.image.shape == (64, 128, 3)
            assert capture.source == f"uvc:{video}"
            levels.append(round(float(capture.image.mean()) / 40))
        assert levels == [1, 2, 3, 1, 2]
    finally:
        camera.close()  # type: ignore[attr-defined]


def test_uvc_refuses_what_it_cannot_open(tmp_path: Path) -> None:
    with pytest.raises(CameraError, match=r"cannot open .*missing\.avi"):
        open_source(f"uvc:{tmp_path / 'missing.avi'}")
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(CameraError, match="not a regular file"):
        open_source(f"uvc:{fifo}")
    junk = tmp_path / "junk.avi"
    junk.write_bytes(b"not a video at all")
    with pytest.raises(CameraError, match="OpenCV cannot open"):
        open_source(f"uvc:{junk}")


def test_uvc_refuses_a_frame_that_is_not_2_to_1(tmp_path: Path) -> None:
    video = write_video(tmp_path / "webcam.avi", level_frames(1, (96, 64)))
    camera = UvcCamera(video)
    with pytest.raises(CameraError, match="96x64 px, not 2:1"):
        camera.capture()
    camera.close()


def test_a_read_that_hangs_times_out(tmp_path: Path) -> None:
    reader = VideoReader(write_video(tmp_path / "v.avi", level_frames(1)), "uvc:test", 0.2)
    release = threading.Event()

    def stuck() -> tuple[bool, np.ndarray | None]:
        release.wait(5.0)
        return False, None

    reader._read = stuck  # type: ignore[method-assign]
    with pytest.raises(CameraError, match=r"uvc:test: no frame within 0\.2 s"):
        reader.read()
    with pytest.raises(CameraError, match="still stuck"):
        reader.read()
    release.set()
    reader.close()


def test_a_failed_read_is_an_error(tmp_path: Path) -> None:
    reader = VideoReader(write_video(tmp_path / "v.avi", level_frames(1)), "uvc:test")
    reader._read = lambda: (False, None)  # type: ignore[method-assign]
    with pytest.raises(CameraError, match="uvc:test: reading a frame failed"):
        reader.read()
    reader.close()


def fisheye_from_equirect(equirect: np.ndarray, fov_deg: float) -> np.ndarray:
    """A dual-fisheye frame (equidistant lenses, front left) rendered from ``equirect``
    (column 0 forward, columns clockwise), written from the lens's side, for the round trip."""
    h, w = equirect.shape[:2]
    side = h  # each circle is h across
    v, u = np.mgrid[0:side, 0:side].astype(float)
    du, dv = u - (side - 1) / 2.0, v - (side - 1) / 2.0
    theta = np.hypot(du, dv) / (side / 2.0) * math.radians(fov_deg) / 2.0
    r = np.maximum(np.hypot(du, dv), 1e-12)
    halves = []
    for axis, right in (((1, 0, 0), (0, -1, 0)), ((-1, 0, 0), (0, 1, 0))):
        down = (0.0, 0.0, -1.0)
        ray = [
            np.cos(theta) * axis[i] + np.sin(theta) * (du / r * right[i] + dv / r * down[i])
            for i in range(3)
        ]
        azimuth = np.arctan2(ray[1], ray[0])
        elevation = np.arcsin(np.clip(ray[2], -1, 1))
        map_x = np.mod(-azimuth * w / (2 * np.pi), w).astype(np.float32)
        map_y = ((h - 1) / 2.0 - elevation * h / np.pi).astype(np.float32)
        halves.append(cv2.remap(equirect, map_x, map_y, cv2.INTER_LINEAR, None, cv2.BORDER_WRAP))
    return np.hstack(halves)


def test_dual_fisheye_round_trip_gives_back_the_equirect() -> None:
    equirect = cv2.resize(cv2.imread(str(PHOTO), cv2.IMREAD_GRAYSCALE), (512, 256))
    fisheye = fisheye_from_equirect(equirect, 190.0)
    map_x, map_y = dual_fisheye_maps((512, 256), 190.0)
    back = cv2.remap(fisheye, map_x, map_y, cv2.INTER_LINEAR)
    band = slice(256 // 6, 256 - 256 // 6)  # elevations within ±60°
    error = np.abs(back[band].astype(float) - equirect[band].astype(float))
    assert np.median(error) < 4.0


def test_uvc_converts_dual_fisheye_frames(tmp_path: Path) -> None:
    video = write_video(tmp_path / "dual.avi", level_frames(1, (128, 64)))
    camera = open_source(f"uvc:{video},layout=dual-fisheye,fov_deg=200")
    assert camera.capture().image.shape == (64, 128, 3)
    camera.close()  # type: ignore[attr-defined]
    with pytest.raises(CameraError, match="layout must be"):
        open_source(f"uvc:{video},layout=cubemap")


def test_files_cycles_through_the_images_of_a_folder(tmp_path: Path) -> None:
    for i, name in enumerate(["b.png", "a.png", "c.jpg"]):
        cv2.imwrite(str(tmp_path / name), np.full((20, 40), 50 * (i + 1), np.uint8))
    (tmp_path / "notes.txt").write_text("not an image")
    (tmp_path / "sub.png").mkdir()
    os.mkfifo(tmp_path / "fifo.png")
    camera = open_source(f"files:{tmp_path}")
    assert isinstance(camera, FilesCamera)
    assert [p.name for p in camera.files] == ["a.png", "b.png", "c.jpg"]
    sources = [camera.capture().source for _ in range(4)]
    assert sources == ["files:a.png", "files:b.png", "files:c.jpg", "files:a.png"]


def test_files_names_a_corrupt_image(tmp_path: Path) -> None:
    (tmp_path / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 20)
    camera = open_source(f"files:{tmp_path}")
    with pytest.raises(CameraError, match=r"broken\.png"):
        camera.capture()
    (tmp_path / "empty").mkdir()
    with pytest.raises(CameraError, match="no image files"):
        open_source(f"files:{tmp_path / 'empty'}")


def test_ptu_stitches_a_sweep_folder(tmp_path: Path) -> None:
    equirect = cv2.imread(str(PHOTO))
    for k in range(12):
        view = view_from_equirect(equirect, 30.0 * k, (320, 240), 240.0)
        cv2.imwrite(str(tmp_path / f"pan_{k:02d}.png"), view)
    camera = open_source(f"ptu:{tmp_path},step_deg=30,focal_px=240")
    first = camera.capture()
    assert first.image.shape[1] == round(2 * math.pi * 240.0)
    assert first.source == f"ptu:{tmp_path}"
    assert camera.capture().image is first.image  # kept while the folder does not change


def test_omni_unwraps_the_real_mirror_image_with_its_calibration() -> None:
    if not OMNI.exists():
        pytest.skip(f"{OMNI} is not here")
    capture = open_source(OMNI_SOURCE).capture()
    width = round(2 * math.pi * 533)
    assert capture.image.shape == (533 - 235 + 1, width)
    # The checkerboard's 9 x 6 inner corners are found in the raw mirror image; their radius and
    # angle around the calibrated centre say where the unwrap must put them (outer rim on top,
    # the heading up in the image, seen mirrored from below), and OpenCV finds the board there.
    raw = cv2.imread(str(OMNI), cv2.IMREAD_GRAYSCALE)
    found, corners = cv2.findChessboardCorners(raw, (9, 6), flags=cv2.CALIB_CB_ADAPTIVE_THRESH)
    assert found
    d = corners.reshape(-1, 2) - OMNI_CENTRE
    radius = np.hypot(d[:, 0], d[:, 1])
    screen_deg = np.degrees(np.arctan2(-d[:, 1], d[:, 0]))
    expected_cols = np.mod((screen_deg - 90.0) / 360.0, 1.0) * width
    expected_rows = 533 - radius
    found, unwrapped = cv2.findChessboardCorners(
        capture.image, (9, 6), flags=cv2.CALIB_CB_ADAPTIVE_THRESH
    )
    assert found
    cols, rows = unwrapped.reshape(-1, 2).T
    assert abs(cols.min() - expected_cols.min()) < 4 and abs(cols.max() - expected_cols.max()) < 4
    assert (
        abs(rows.min() - expected_rows.min()) < 2 and abs(rows.max() - expected_rows.max()) < 2
    )  # 1.7, 0.4


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("webcam:0", "unknown kind"),
        ("files:", "needs an argument"),
        ("sim", "needs the sim robot"),
        ("sim:x", "sim takes no argument"),
        ("ptu:/tmp,step_deg=-5", "step_deg must be a positive number"),
        ("files:/tmp,step_deg=5", "files takes no option step_deg"),
        ("omni:1,2", "four numbers"),
        ("files:/no/such/folder", "is not a folder"),
        ("uvc:/no/such.avi", "cannot open"),
    ],
)
def test_malformed_source_texts_are_one_line_errors(text: str, message: str) -> None:
    with pytest.raises(CameraError, match=message) as raised:
        open_source(text)
    assert text in str(raised.value) or "/no/such" in str(raised.value)
    assert "\n" not in str(raised.value)


def test_sim_is_the_robots_own_capture() -> None:
    class Fake:
        def capture(self) -> Capture:
            return Capture(np.zeros((4, 8), np.uint8), 1.0, "sim:fake")

    camera = open_source("sim", Fake())  # type: ignore[arg-type]
    assert camera.capture().source == "sim:fake"


def test_a_dangling_symlink_in_a_files_folder_is_skipped(tmp_path):
    cv2.imwrite(str(tmp_path / "a.png"), np.full((8, 16), 50, np.uint8))
    (tmp_path / "b.png").symlink_to(tmp_path / "gone.png")
    assert [p.name for p in image_files(tmp_path, "files:test")] == ["a.png"]
