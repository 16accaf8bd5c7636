"""Real 360° photographs (Poly Haven, CC0; shipped in robot/data/photos): the stored room is
recognised after a yaw roll, an exposure change (down to a quarter of the light), noise and an
occluded sector, and a room that
is not in the map never comes out localized.

The map holds two places per room: the photo itself, and the photo projected onto the room's
box and seen from 1.2 m away (real texture, approximate geometry). Everything runs at 512 x 256
to stay fast; the likelihood is calibrated on this map as `toploc map build` would.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from localizer.belief import LocalizationState
from localizer.calibration import calibrate
from localizer.cameras import CameraSpec
from localizer.features import extract_with_camera
from localizer.loaded_map import LoadedMap
from localizer.localizer import Localizer, LocalizerConfig
from localizer.robot_protocol import Pose2D
from mapdb.records import FingerprintTable, MapSnapshot, Place
from robot.photo_library import load_photo, photo_room
from robot.photo_room import render_photo_room
from robot.render import PanoramaCamera

MAP_ROOMS = (
    "brown_photostudio_01",
    "brown_photostudio_02",
    "brown_photostudio_06",
    "vestibule",
    "thatch_chapel",
    "autoshop_01",
)
UNKNOWN_ROOMS = ("christmas_photo_studio_07", "drachenfels_cellar")
WIDTH_PX = 512


def grey_photo(name: str) -> np.ndarray:
    photo = cv2.cvtColor(load_photo(name), cv2.COLOR_RGB2GRAY)
    return cv2.resize(photo, (WIDTH_PX, WIDTH_PX // 2), interpolation=cv2.INTER_AREA)


def moved_view(name: str, offset_m: float) -> np.ndarray:
    """The photo's room seen from ``offset_m`` along +x of the capture point."""
    room = photo_room(name)
    x_m, y_m = room.capture_m
    camera = PanoramaCamera(WIDTH_PX, WIDTH_PX // 2, projection="equirect", height_m=1.4)
    rgb = render_photo_room(load_photo(name), room, Pose2D(x_m + offset_m, y_m, 0.0), camera)
    return cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)


@pytest.fixture(scope="module")
def localizer() -> Localizer:
    fingerprints, rooms = [], []
    for name in MAP_ROOMS:
        for image in (grey_photo(name), moved_view(name, 1.2)):
            fingerprints.append(extract_with_camera(image, CameraSpec(), "sift"))
            rooms.append(name)
    ids = list(range(1, len(fingerprints) + 1))
    table = FingerprintTable.stack("sift", ids, rooms, fingerprints)
    places = tuple(Place(i, r) for i, r in zip(ids, rooms, strict=True))
    snapshot = MapSnapshot(Path("photos"), table, places, MAP_ROOMS, ())
    loaded = LoadedMap.from_snapshot(snapshot)
    likelihood, _ = calibrate(loaded)
    return Localizer(loaded, LocalizerConfig(likelihood=likelihood))


def exposure(image: np.ndarray, gain: float, gamma: float) -> np.ndarray:
    values = 255.0 * (gain * image / 255.0) ** gamma
    return np.clip(values, 0, 255).astype(np.uint8)


CHANGES = {
    "yaw roll 117°": lambda im: np.roll(im, int(WIDTH_PX * 117 / 360), axis=1),
    "darker": lambda im: exposure(im, 0.55, 1.3),
    "brighter": lambda im: exposure(im, 1.6, 0.8),
    "a quarter of the light": lambda im: exposure(im, 0.25, 1.0),
    "noise": lambda im: np.clip(
        im + np.random.default_rng(0).normal(0, 10, im.shape), 0, 255
    ).astype(np.uint8),
    "a quarter occluded": lambda im: np.where(
        np.arange(im.shape[1]) < im.shape[1] // 4, np.uint8(128), im
    ).astype(np.uint8),
}


@pytest.mark.parametrize("change", sorted(CHANGES))
@pytest.mark.parametrize("room", ["brown_photostudio_02", "vestibule"])
def test_the_stored_room_is_recognised_after(localizer: Localizer, room: str, change: str) -> None:
    query = CHANGES[change](moved_view(room, -0.6))
    belief, _ = localizer.localize_once(query)
    assert belief.top[0] == room
    assert belief.state is LocalizationState.LOCALIZED


@pytest.mark.parametrize("room", UNKNOWN_ROOMS)
def test_a_room_not_in_the_map_is_never_localized(localizer: Localizer, room: str) -> None:
    for query in (grey_photo(room), moved_view(room, 0.8)):
        belief, _ = localizer.localize_once(query)
        assert belief.state is not LocalizationState.LOCALIZED, belief.ranked()[:3]
