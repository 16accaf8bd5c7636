"""Place evidence on rendered panoramas of the square world, stored in a real map database."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from homing.bearings import wrap_angle_rad
from localizer.evidence import EvidenceParams, PlaceEvidence, QueryEvidence, place_evidence
from localizer.features import extract_preset
from localizer.robot_protocol import Pose2D
from localizer.verification import verify
from mapdb.database import MapDatabase
from mapdb.loading import load_fingerprint_table
from mapdb.records import Fingerprint, FingerprintTable, NewPlace
from robot.conditions import get_condition
from robot.render import PanoramaCamera, render_panorama
from robot.scene import build_scene
from robot.worlds import make_world

CAMERA = PanoramaCamera(width_px=1024, height_px=192)
# (x_m, y_m, heading_deg) in the square room's frame, at capture places clear of furniture.
MAP_PLACES = ((2.5, 0.7, 0.0), (3.0, 2.2, 90.0), (0.5, 2.7, -120.0), (1.5, 1.7, 160.0))


class Square:
    """The square world's scene and a renderer of SIFT fingerprints at room-frame poses."""

    def __init__(self) -> None:
        self.world = make_world("square", 0)
        self.scene = build_scene(self.world)

    def fingerprint(
        self, x_m: float, y_m: float, heading_deg: float, condition: str = "default"
    ) -> Fingerprint:
        pose = self.world.building_pose("square", Pose2D(x_m, y_m, math.radians(heading_deg)))
        image = render_panorama(
            self.scene, pose, CAMERA, get_condition(condition), seed=(3, int(x_m * 100)), grey=True
        )
        return extract_preset(image, "sift")


@pytest.fixture(scope="module")
def square() -> Square:
    return Square()


@pytest.fixture(scope="module")
def square_table(square: Square, tmp_path_factory: pytest.TempPathFactory) -> FingerprintTable:
    path = tmp_path_factory.mktemp("evidence") / "map.db"
    with MapDatabase.open(path) as map_db:
        for i, (x, y, heading) in enumerate(MAP_PLACES):
            place = NewPlace("square", f"{i:064x}", f"square/{i}", x, y, heading)
            map_db.add_place(place, [square.fingerprint(x, y, heading)])
        return load_fingerprint_table(map_db, "sift")


def test_yaw_between_two_headings_at_one_spot(square: Square) -> None:
    place = square.fingerprint(2.0, 2.2, 10.0)
    query = square.fingerprint(2.0, 2.2, 75.0, condition="dim")
    from localizer.matching import match_descriptors

    pairs = match_descriptors(query.descriptors, place.descriptors)
    result = verify(query.rays(), place.rays(), pairs)
    assert result.inliers >= 30
    assert abs(math.degrees(wrap_angle_rad(result.yaw_rad - math.radians(65.0)))) < 2.0


@pytest.mark.parametrize(
    ("query_pose", "expected"), [((2.65, 0.85, 35.0), 0), ((0.6, 2.55, -60.0), 2)]
)
def test_right_place_ranks_first_with_its_yaw(
    square: Square,
    square_table: FingerprintTable,
    query_pose: tuple[float, float, float],
    expected: int,
) -> None:
    query = square.fingerprint(*query_pose, condition="dim")
    evidence = place_evidence(query, square_table, EvidenceParams(seed=3))
    assert len(evidence.places) == len(MAP_PLACES)
    inliers = [e.inliers for e in evidence.places]
    assert inliers == sorted(inliers, reverse=True)
    best = evidence.best
    assert best is not None and best.place_id == int(square_table.place_ids[expected])
    assert best.room == "square"
    assert best.inliers > evidence.places[1].inliers
    assert best.inlier_pairs.shape == (best.inliers, 2)
    yaw_deg = query_pose[2] - MAP_PLACES[expected][2]
    assert abs(math.degrees(wrap_angle_rad(best.yaw_rad - math.radians(yaw_deg)))) < 3.0
    assert set(evidence.timing_ms) == {"retrieval", "verification"}
    assert evidence.timing_ms["retrieval"] == 0.0 and evidence.timing_ms["verification"] > 0


def test_empty_query_gives_zero_evidence(square_table: FingerprintTable) -> None:
    empty = Fingerprint.empty("sift", CAMERA.width_px, CAMERA.height_px)
    evidence = place_evidence(empty, square_table)
    assert len(evidence.places) == len(MAP_PLACES)
    assert all(e.matches == 0 and e.inliers == 0 and np.isnan(e.yaw_rad) for e in evidence.places)


def test_empty_map_gives_no_places(square: Square, tmp_path: Path) -> None:
    with MapDatabase.open(tmp_path / "empty.db") as map_db:
        table = load_fingerprint_table(map_db, "sift")
    evidence = place_evidence(square.fingerprint(2.0, 1.7, 0.0), table)
    assert evidence == QueryEvidence((), evidence.timing_ms)
    assert evidence.best is None


def test_detector_mismatch_is_named(square_table: FingerprintTable) -> None:
    mser = Fingerprint.empty("mser", CAMERA.width_px, CAMERA.height_px)
    with pytest.raises(ValueError, match="'mser' but the table holds 'sift'"):
        place_evidence(mser, square_table)


def test_params_are_validated() -> None:
    with pytest.raises(ValueError, match="min_matches"):
        EvidenceParams(min_matches=3)
    with pytest.raises(ValueError, match="max_error_rad"):
        EvidenceParams(max_error_rad=0.0)
    empty = PlaceEvidence(1, "a", 0, 0, float("nan"), np.zeros((0, 2)), 0.0)
    assert isinstance(empty, PlaceEvidence)


def test_candidates_on_two_threads_give_the_same_evidence(
    square: Square, square_table: FingerprintTable
) -> None:
    query = square.fingerprint(2.0, 1.5, 40.0, condition="dim")
    one = place_evidence(query, square_table, EvidenceParams(threads=1)).places
    two = place_evidence(query, square_table, EvidenceParams(threads=2)).places
    assert [(e.place_id, e.matches, e.inliers) for e in one] == [
        (e.place_id, e.matches, e.inliers) for e in two
    ]
    np.testing.assert_array_equal([e.yaw_rad for e in one], [e.yaw_rad for e in two])
    with pytest.raises(ValueError, match="threads"):
        EvidenceParams(threads=0)
