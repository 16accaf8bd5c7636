"""Camera models: rows ↔ elevations, pixels ↔ rays, choosing a model, band and half masks
(columns ↔ bearings: test_homing_bearings)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from homing.bearings import bearing_rad_from_column
from homing.cameras import (
    Cylinder,
    Equirect,
    camera_model,
    focal_from_vfov_px,
    pixels_from_rays,
    rays_from_pixels,
)
from localizer.cameras import (
    CameraSpec,
    NotPanoramaError,
    elevation_mask,
    horizon_band_mask,
    panorama_kind,
    parse_camera,
    rows_kept,
    rows_mask,
)
from mapdb.records import Fingerprint


@given(
    height=st.integers(min_value=1, max_value=2000),
    focal=st.one_of(st.none(), st.floats(min_value=1.0, max_value=5000.0)),
    frac=st.floats(min_value=0.0, max_value=1.0),
)
def test_row_elevation_round_trip(height: int, focal: float | None, frac: float) -> None:
    cyl = Cylinder(width_px=1024, height_px=height, focal_px=focal)
    y = frac * (height - 1)
    assert cyl.row_px(cyl.elevation_rad(y)) == pytest.approx(y, abs=1e-6)


def test_cylinder_defaults_and_elevation_sign() -> None:
    cyl = Cylinder(width_px=628, height_px=101)
    assert cyl.f_px == pytest.approx(628 / (2 * np.pi))
    assert cyl.horizon_px == 50.0
    e = cyl.elevation_rad([0.0, 50.0, 100.0])
    assert e[0] > 0 and e[1] == 0 and e[2] < 0
    # One row at the horizon subtends one column's angle (square pixels on the cylinder).
    assert cyl.elevation_rad(49.0) == pytest.approx(2 * np.pi / 628, rel=1e-4)


@pytest.mark.parametrize("band_deg", [0.0, 5.0, 10.0, 20.0, 45.0])
def test_horizon_band_mask_rows(band_deg: float) -> None:
    cyl = Cylinder(width_px=512, height_px=96, focal_px=60.0, horizon_row_px=40.0)
    rows = np.arange(96)
    mask = horizon_band_mask(rows, cyl, band_deg)
    half_px = 60.0 * np.tan(np.deg2rad(band_deg))
    np.testing.assert_array_equal(mask, np.abs(rows - 40.0) <= half_px + 1e-9)
    kept = np.flatnonzero(mask)
    assert np.all(np.diff(kept) == 1)  # one contiguous band around the horizon
    assert 40 in kept


def test_horizon_band_none_keeps_all_and_rejects_bad() -> None:
    cyl = Cylinder(width_px=64, height_px=10)
    assert horizon_band_mask(np.arange(10), cyl, None).all()
    with pytest.raises(ValueError, match="band_deg"):
        horizon_band_mask(np.arange(10), cyl, 90.0)


@given(height=st.integers(min_value=1, max_value=500))
def test_lower_upper_partition(height: int) -> None:
    cyl = Cylinder(width_px=64, height_px=height)
    y = np.arange(height, dtype=float)
    lower, upper = rows_mask(y, cyl, "lower"), rows_mask(y, cyl, "upper")
    assert not np.any(lower & upper)
    assert np.all(lower | upper)
    assert rows_mask(y, cyl, "all").all()
    assert np.all(y[lower] >= (height - 1) / 2) and np.all(y[upper] < (height - 1) / 2)


def test_bad_geometry_arguments() -> None:
    with pytest.raises(ValueError, match="width"):
        bearing_rad_from_column(0.0, 0)
    with pytest.raises(ValueError, match="focal_px"):
        Cylinder(width_px=10, height_px=10, focal_px=-1.0)
    with pytest.raises(ValueError, match="rows must be one of"):
        rows_mask([1.0], Cylinder(10, 10), "middle")  # type: ignore[arg-type]


def test_equirect_rows_are_linear_in_elevation() -> None:
    sphere = Equirect(width_px=2048, height_px=1024)
    assert sphere.horizon_px == 511.5
    # the image's top edge is the zenith, its bottom edge the nadir, one row is 180°/H
    np.testing.assert_allclose(
        sphere.elevation_rad([-0.5, 511.5, 1023.5]), [np.pi / 2, 0, -np.pi / 2]
    )
    assert sphere.elevation_rad(0.0) - sphere.elevation_rad(1.0) == pytest.approx(np.pi / 1024)


@given(
    x=st.floats(min_value=0.0, max_value=1023.9),
    y=st.floats(min_value=0.0, max_value=511.0),
    equirect=st.booleans(),
)
def test_pixels_rays_round_trip(x: float, y: float, equirect: bool) -> None:
    camera = Equirect(1024, 512) if equirect else Cylinder(1024, 512)
    rays = rays_from_pixels(camera, [[x, y]])
    np.testing.assert_allclose(np.linalg.norm(rays, axis=1), 1.0)
    back = pixels_from_rays(camera, rays)[0]
    assert min(abs(back[0] - x), 1024 - abs(back[0] - x)) < 1e-6  # columns wrap at 360°
    assert back[1] == pytest.approx(y, abs=1e-6)


def test_rays_follow_rep103() -> None:
    # column 0 looks ahead, a quarter of the width clockwise is the robot's right (-y)
    rays = rays_from_pixels(Equirect(400, 200), [[0.0, 99.5], [100.0, 99.5], [0.0, -0.5]])
    np.testing.assert_allclose(rays, [[1, 0, 0], [0, -1, 0], [0, 0, 1]], atol=1e-12)


@pytest.mark.parametrize(
    ("text", "kind"),
    [
        ("auto", "auto"),
        ("equirect", "equirect"),
        (" cylinder ", "cylinder"),
        ("omni:674,546,235,600", "omni"),
    ],
)
def test_parse_camera(text: str, kind: str) -> None:
    spec = parse_camera(text)
    assert spec.kind == kind
    assert parse_camera(str(spec)) == spec


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("fisheye", "expected auto, cylinder, equirect or omni"),
        ("equirect:2", "expected auto"),
        ("omni:1,2,3", "four numbers"),
        ("omni:1,2,x,4", "four numbers"),
        ("omni:100,100,60,40", "0 <= R0 < R1"),
        ("omni:100,nan,10,40", "finite"),
    ],
)
def test_a_bad_camera_names_the_text(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=message) as raised:
        parse_camera(text)
    assert repr(text) in str(raised.value)


def test_auto_reads_a_two_to_one_image_as_a_sphere() -> None:
    auto = CameraSpec()
    assert panorama_kind(auto, 2048, 1024) == "equirect"
    assert panorama_kind(auto, 1024, 192) == "cylinder"
    assert panorama_kind(CameraSpec("cylinder"), 2048, 1024) == "cylinder"
    assert panorama_kind(parse_camera("omni:5,5,1,4"), 2048, 1024) == "cylinder"  # unwrapped


def test_a_fingerprint_carries_its_camera() -> None:
    old = Fingerprint.empty("sift", 1024, 192)  # made before cameras were recorded
    assert old.camera == Cylinder(1024, 192)
    sphere = Fingerprint.empty("sift", 1024, 512, params={"camera": "equirect"})
    assert sphere.camera == Equirect(1024, 512)
    with pytest.raises(ValueError, match="unknown camera 'fisheye'"):
        Fingerprint.empty("sift", 10, 5, params={"camera": "fisheye"})


def test_a_selection_keeps_the_fingerprints_camera_object() -> None:
    fp = Fingerprint.empty("sift", 1024, 192)
    assert fp.select(np.zeros(0, dtype=bool)).camera is fp.camera


def test_the_factory_builds_each_model_and_refuses_others() -> None:
    assert camera_model("cylinder", 512, 96, 60.0) == Cylinder(512, 96, 60.0)
    assert camera_model("equirect", 512, 256) == Equirect(512, 256)
    with pytest.raises(ValueError, match="unknown camera 'pinhole'"):
        camera_model("pinhole", 640, 480)
    with pytest.raises(ValueError, match="no focal_px"):
        camera_model("equirect", 512, 256, focal_px=80.0)


def test_a_vertical_field_of_view_sets_the_cylinder_focal_length() -> None:
    cylinder = Cylinder(256, 64, focal_from_vfov_px(64, 60.0))
    assert np.rad2deg(cylinder.elevation_rad(-0.5)) == pytest.approx(30.0)  # the top edge
    assert np.rad2deg(cylinder.elevation_rad(63.5)) == pytest.approx(-30.0)  # the bottom edge
    np.testing.assert_allclose(
        cylinder.tan_elevation(np.arange(64)), np.tan(cylinder.elevation_rad(np.arange(64)))
    )


@pytest.mark.parametrize("size", [(1024, 192), (512, 96), (2048, 1024), (1000, 400)])
def test_auto_takes_every_panorama_size_toploc_makes(size: tuple[int, int]) -> None:
    assert panorama_kind(CameraSpec(), *size) in ("cylinder", "equirect")


@pytest.mark.parametrize("size", [(640, 480), (1920, 1080), (1000, 1000), (4000, 1800)])
def test_auto_refuses_an_image_that_is_no_360_panorama(size: tuple[int, int]) -> None:
    with pytest.raises(NotPanoramaError, match=r"photo.jpg: \d+x\d+ px .* --camera"):
        panorama_kind(CameraSpec(), *size, source="photo.jpg")


def test_the_refusal_says_what_a_panorama_looks_like_and_how_to_name_the_camera() -> None:
    with pytest.raises(NotPanoramaError) as refused:
        panorama_kind(CameraSpec(), 640, 480, source="photo.jpg")
    assert str(refused.value) == (
        "photo.jpg: 640x480 px (1.33:1) is not a 360° panorama: an equirectangular one is 2:1 "
        "(e.g. 2048x1024), a cylindrical one at least 2.5:1 (e.g. 1024x192); if it is one, "
        "name its camera with --camera equirect or --camera cylinder"
    )


def test_a_named_camera_is_taken_at_its_word() -> None:
    assert panorama_kind(CameraSpec("cylinder"), 640, 480) == "cylinder"
    assert panorama_kind(CameraSpec("equirect"), 640, 480) == "equirect"
    assert panorama_kind(parse_camera("omni:320,240,20,200"), 640, 480) == "cylinder"


def test_all_row_filters_at_once_are_each_filter_in_turn() -> None:
    sphere = Equirect(360, 180)
    rows = np.arange(180)
    both = rows_kept(rows, sphere, 30.0, -20.0, 60.0, "lower")
    one_by_one = (
        horizon_band_mask(rows, sphere, 30.0)
        & elevation_mask(rows, sphere, -20.0, 60.0)
        & rows_mask(rows, sphere, "lower")
    )
    np.testing.assert_array_equal(both, one_by_one)
    assert 0 < both.sum() < 180


def test_elevation_mask_leaves_out_nadir_and_zenith() -> None:
    sphere = Equirect(360, 180)
    rows = np.arange(180)
    keep = elevation_mask(rows, sphere, -50.0, 60.0)
    elevation_deg = np.rad2deg(sphere.elevation_rad(rows))
    assert np.all((elevation_deg[keep] >= -50) & (elevation_deg[keep] <= 60))
    assert keep.sum() == pytest.approx(110, abs=1)  # one row per degree
    assert np.all(elevation_mask(rows, sphere, None, None))
