"""Contrast equalisation before detection (CLAHE in full-width bands): exact under a yaw roll, a
dim copy of a real photo keeps its keypoints, and a query (or a new place) is equalised as the
map's places were, also for a map written before the equalisation existed."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_localizer_real_photos import exposure

from localizer.cameras import CameraSpec
from localizer.features import (
    ExtractionParams,
    equalised,
    extract_with_camera,
    matching_overrides,
)
from localizer.loaded_map import LoadedMap
from localizer.localizer import Localizer
from mapdb.database import MapDatabase
from mapdb.records import Fingerprint, FingerprintTable, MapSnapshot, NewPlace, Place
from robot.photo_library import load_photo
from toploc.extraction import map_overrides


def photo(name: str = "vestibule") -> np.ndarray:
    grey = cv2.cvtColor(load_photo(name), cv2.COLOR_RGB2GRAY)
    return cv2.resize(grey, (512, 256), interpolation=cv2.INTER_AREA)


def unequalised_record(fingerprint: Fingerprint) -> Fingerprint:
    """``fingerprint`` as a map written before the equalisation stored it: no contrast keys."""
    old = {k: v for k, v in fingerprint.params.items() if not k.startswith("clahe_")}
    return replace(fingerprint, params=old)


@given(seed=st.integers(0, 2**16), shift_px=st.integers(0, 255))
def test_equalisation_commutes_with_a_yaw_roll(seed: int, shift_px: int) -> None:
    image = np.random.default_rng(seed).integers(0, 120, (64, 256), dtype=np.uint8)
    params = ExtractionParams()
    rolled_after = np.roll(equalised(image, params), shift_px, axis=1)
    np.testing.assert_array_equal(equalised(np.roll(image, shift_px, axis=1), params), rolled_after)


def test_a_clip_limit_of_zero_leaves_the_image_as_given() -> None:
    image = photo()
    assert equalised(image, ExtractionParams(clahe_clip_limit=0.0)) is image


def test_a_photo_at_a_quarter_of_the_light_keeps_its_keypoints_only_when_equalised() -> None:
    lit, dim = photo(), exposure(photo(), 0.25, 1.0)

    def kept(clip: float) -> float:
        n = [
            extract_with_camera(im, CameraSpec(), "sift", clahe_clip_limit=clip).n
            for im in (lit, dim)
        ]
        return n[1] / n[0]

    # measured: 54 % of the lit photo's keypoints equalised, 2.5 % as given
    assert kept(2.0) >= 0.4
    assert kept(2.0) >= 5 * kept(0.0)


def test_a_record_without_the_contrast_fields_means_no_equalisation() -> None:
    new = extract_with_camera(photo(), CameraSpec(), "sift")
    # read at the sphere's default width: no width is passed on
    assert matching_overrides(new.params) == {
        "clahe_clip_limit": 2.0, "clahe_band_deg": 45.0, "max_keypoints": 1000
    }  # fmt: skip
    assert matching_overrides(unequalised_record(new).params)["clahe_clip_limit"] == 0.0


def test_a_query_keeps_the_map_s_keypoint_cap_or_its_absence() -> None:
    capped = extract_with_camera(photo(), CameraSpec(), "sift", max_keypoints=300)
    assert capped.n == 300 and matching_overrides(capped.params)["max_keypoints"] == 300
    uncapped = extract_with_camera(photo(), CameraSpec(), "sift", max_keypoints=None)
    assert uncapped.n > 300 and matching_overrides(uncapped.params)["max_keypoints"] is None


def _localizer(fingerprints: list[Fingerprint]) -> Localizer:
    ids = list(range(1, len(fingerprints) + 1))
    rooms = ["vestibule"] * len(fingerprints)
    table = FingerprintTable.stack("sift", ids, rooms, fingerprints)
    places = tuple(Place(i, r) for i, r in zip(ids, rooms, strict=True))
    return Localizer(
        LoadedMap.from_snapshot(MapSnapshot(Path("m"), table, places, ("vestibule",), ()))
    )


@pytest.mark.parametrize("old_map", [False, True])
def test_a_query_is_equalised_as_the_map_was(old_map: bool) -> None:
    place = extract_with_camera(
        photo(), CameraSpec(), "sift", clahe_clip_limit=0.0 if old_map else 2.0
    )
    localizer = _localizer([unequalised_record(place) if old_map else place])
    query = localizer.extract(photo())
    assert query.params["clahe_clip_limit"] == (0.0 if old_map else 2.0)


def test_a_new_place_follows_the_places_already_in_the_map(tmp_path: Path) -> None:
    old = unequalised_record(
        extract_with_camera(photo(), CameraSpec(), "sift", clahe_clip_limit=0.0)
    )
    with MapDatabase.open(tmp_path / "map.db") as map_db:
        assert map_overrides(map_db) == {}  # an empty map: the defaults
        map_db.add_place(NewPlace("vestibule", "ab" * 32, "a.png"), [old])
        assert map_overrides(map_db)["clahe_clip_limit"] == 0.0


def test_a_query_is_read_at_the_width_the_map_s_places_were_read_at() -> None:
    wide = cv2.resize(photo(), (1536, 768), interpolation=cv2.INTER_CUBIC)
    place = extract_with_camera(wide, CameraSpec(), "sift", max_width_px=1536)
    query = _localizer([place]).extract(wide)
    assert query.params["max_width_px"] == 1536
    assert query.keypoints_xy[:, 0].max() > 1024  # in the full-width image's pixels


def test_a_cylinder_map_leaves_a_sphere_query_at_its_camera_s_width() -> None:
    cylinder = extract_with_camera(photo()[64:192], CameraSpec(), "sift")
    assert "max_width_px" not in matching_overrides(cylinder.params)
    query = _localizer([cylinder]).extract(cv2.resize(photo(), (2048, 1024)))
    assert query.params["max_width_px"] == 1024


def test_a_sphere_map_at_the_default_width_leaves_a_wide_cylinder_query_at_full_width() -> None:
    sphere = extract_with_camera(photo(), CameraSpec(), "sift")  # read at up to 1024 px
    query = _localizer([sphere]).extract(cv2.resize(photo()[64:192], (1536, 384)))
    assert query.params.get("max_width_px") is None  # the cylinder's default: never shrunk
