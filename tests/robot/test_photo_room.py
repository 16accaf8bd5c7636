"""Photo rooms: a real 360° photo projected onto a box room and rendered from other points."""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from localizer.robot_protocol import Pose2D
from mapdb.dataset import read_edges, read_manifest
from robot.photo_dataset import photo_places, render_photo_dataset
from robot.photo_library import load_photo, photo_room, photo_room_names
from robot.photo_room import PhotoRoom, box_exit_m, photo_pixel_of, render_photo_room
from robot.render import PanoramaCamera
from toploc.commands.dataset import dataset

EQUIRECT = PanoramaCamera(256, 128, height_m=1.4, projection="equirect")
ROOM = PhotoRoom("test", (6.0, 5.0), 3.0, (2.5, 2.0))


def test_seventeen_indoor_photos_ship_as_package_data() -> None:
    names = photo_room_names()
    assert len(names) == 17
    assert "vestibule" in names and "noon_grass" not in names
    photo_dir = resources.files("robot") / "data" / "photos"
    assert (photo_dir / "README.md").is_file()
    assert "CC0" in (photo_dir / "README.md").read_text(encoding="utf-8")
    photo = load_photo("studio_small_05")
    assert photo.shape == (512, 1024, 3) and photo.dtype == np.uint8
    with pytest.raises(ValueError, match="unknown photo room 'kitchen'"):
        photo_room("kitchen")


def test_render_from_the_capture_point_is_the_photo() -> None:
    room = photo_room("brown_photostudio_01")
    photo = load_photo(room.name)
    pose = Pose2D(*room.capture_m, 0.0)
    full = PanoramaCamera(1024, 512, height_m=room.capture_height_m, projection="equirect")
    assert np.array_equal(render_photo_room(photo, room, pose, full), photo)
    small = render_photo_room(photo, room, pose, EQUIRECT).astype(int)
    expected = cv2.resize(photo, (256, 128), interpolation=cv2.INTER_AREA).astype(int)
    assert np.abs(small - expected).max() <= 1


def test_turning_rolls_the_render() -> None:
    photo = load_photo("vestibule")
    shift = 32  # columns of 256: 45 degrees
    a = render_photo_room(photo, ROOM, Pose2D(1.5, 3.0, 0.3), EQUIRECT).astype(int)
    turned = Pose2D(1.5, 3.0, 0.3 + 2 * math.pi * shift / EQUIRECT.width_px)
    b = render_photo_room(photo, ROOM, turned, EQUIRECT).astype(int)
    assert np.abs(np.roll(a, shift, axis=1) - b).mean() < 1.0


def test_a_wall_point_seen_from_two_viewpoints_maps_to_one_photo_pixel() -> None:
    """Cast each viewpoint's ray to a known wall point; both land on the same photo pixel, the
    one in the direction of that point from the capture point."""
    wall_point = np.array([6.0, 1.2, 2.1])  # on the +x wall
    capture = ROOM.capture_point_m
    pixels = []
    for origin in (np.array([1.0, 4.0, 1.4]), np.array([4.5, 0.8, 0.9])):
        exit_point = box_exit_m(ROOM, origin, (wall_point - origin) * 0.37)
        assert np.allclose(exit_point, wall_point)
        pixels.append(photo_pixel_of(ROOM, exit_point, (1024, 512)))
    assert np.allclose(pixels[0], pixels[1])
    v = wall_point - capture
    azimuth = math.atan2(v[1], v[0])
    elevation = math.atan2(v[2], math.hypot(v[0], v[1]))
    assert pixels[0][0] == pytest.approx((-azimuth * 1024 / (2 * math.pi)) % 1024)
    assert pixels[0][1] == pytest.approx(255.5 - elevation * 512 / math.pi)


def test_a_landmark_renders_at_the_column_and_row_of_the_conventions() -> None:
    """A red square painted on the photo where a wall point is seen from the capture point shows
    up, from another pose, at column ``-W * bearing / (2 pi)`` and row of its elevation."""
    photo = np.full((512, 1024, 3), 128, np.uint8)
    wall_point = np.array([6.0, 3.5, 2.2])
    x, y = photo_pixel_of(ROOM, wall_point, (1024, 512))
    cv2.circle(photo, (round(float(x)), round(float(y))), 6, (255, 0, 0), -1)
    pose = Pose2D(3.0, 1.5, math.radians(25.0))
    image = render_photo_room(photo, ROOM, pose, EQUIRECT)
    red = (image[..., 0] > 200) & (image[..., 1] < 80)
    rows, cols = np.nonzero(red)
    assert len(rows) > 0
    v = wall_point - np.array([pose.x_m, pose.y_m, EQUIRECT.height_m])
    bearing = math.atan2(v[1], v[0]) - pose.heading_rad
    elevation = math.atan2(v[2], math.hypot(v[0], v[1]))
    w, h = EQUIRECT.width_px, EQUIRECT.height_px
    assert cols.mean() == pytest.approx((-w * bearing / (2 * math.pi)) % w, abs=1.0)
    assert rows.mean() == pytest.approx((h - 1) / 2 - elevation * h / math.pi, abs=1.0)


def test_a_cylinder_render_and_bad_input() -> None:
    photo = load_photo("studio_small_05")
    room = photo_room("studio_small_05")
    image = render_photo_room(photo, room, Pose2D(1.0, 1.0), PanoramaCamera(256, 48, height_m=1.4))
    assert image.shape == (48, 256, 3)
    with pytest.raises(ValueError, match="outside photo room"):
        render_photo_room(photo, room, Pose2D(7.0, 1.0), EQUIRECT)
    with pytest.raises(ValueError, match="equirectangular"):
        render_photo_room(photo[:, :600], room, Pose2D(1.0, 1.0), EQUIRECT)
    with pytest.raises(ValueError, match="capture point"):
        PhotoRoom("bad", (4.0, 4.0), 3.0, (5.0, 1.0))


def test_places_include_the_capture_point_and_keep_off_the_walls() -> None:
    places = photo_places(ROOM, 1.5, 0.6)
    assert places[0] == ROOM.capture_m
    xs, ys = np.array(places[1:]).T
    assert xs.min() >= 0.6 and xs.max() <= 5.4 and ys.min() >= 0.6 and ys.max() <= 4.4
    assert len(places) == 1 + 4 * 3


def test_a_photo_dataset_and_its_command(tmp_path: Path) -> None:
    camera = PanoramaCamera(64, 32, height_m=1.4, projection="equirect")
    manifest = render_photo_dataset(
        tmp_path / "ds", ["studio_small_05"], 2.0, "dim", 3, None, camera, progress=False
    )
    rows = read_manifest(manifest.parent)
    room = photo_room("studio_small_05")
    assert [(r.x_m, r.y_m) for r in rows] == photo_places(room, 2.0)
    assert {r.room for r in rows} == {"studio_small_05"}
    assert read_edges(manifest.parent) == []
    assert cv2.imread(str(manifest.parent / rows[0].image)).shape == (32, 64, 3)
    result = CliRunner().invoke(
        dataset,
        ["render", str(tmp_path / "cli"), "--world", "photos", "--rooms", "drachenfels_cellar",
         "--width", "64", "--spacing", "3"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "drachenfels_cellar: 7 places"  # 3 x 2 grid and the capture point in result.output
    bad = CliRunner().invoke(dataset, ["render", str(tmp_path / "x"), "--world", "house",
                                       "--rooms", "hall"])  # fmt: skip
    assert bad.exit_code != 0 and "--world photos only" in bad.output
