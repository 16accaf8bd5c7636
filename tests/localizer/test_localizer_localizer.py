"""The localizer on a small rendered map: load, observe, update, one-shot belief."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from localizer.belief import LocalizationState
from localizer.cameras import CameraSpec
from localizer.features import extract_with_camera
from localizer.likelihood import RatioLikelihood
from localizer.loaded_map import LoadedMap
from localizer.localizer import PARTIAL_VIEW_RATIO, Localizer, to_grey
from localizer.robot_protocol import Pose2D
from mapdb.database import MapDatabase
from mapdb.loading import load_snapshot
from mapdb.records import FingerprintTable, MapSnapshot, Place
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.worlds import make_world

CAMERA = PanoramaCamera(512, 96)


@pytest.fixture(scope="module")
def localizer(building_map) -> Localizer:
    db_path, _ = building_map
    return Localizer(LoadedMap.from_snapshot(load_snapshot(db_path)))


def capture_in(room: str, x_m: float, y_m: float, heading_deg: float) -> object:
    world = make_world("building")
    pose = world.building_pose(room, Pose2D(x_m, y_m, math.radians(heading_deg)))
    return SimulatedRobot(world, pose, camera=CAMERA, seed=5).capture().image


def test_the_loaded_map_has_every_room_with_places_and_the_graph(localizer: Localizer):
    assert set(localizer.map.rooms) == {
        "corridor", "kitchen", "office_a", "office_b", "seminar", "storage"
    }  # fmt: skip
    assert ("corridor", "kitchen") in localizer.map.edges
    assert localizer.map.image_size_px == (512, 96)


def test_a_kitchen_panorama_between_places_is_placed_in_the_kitchen(localizer: Localizer):
    belief, observation = localizer.localize_once(capture_in("kitchen", 2.0, 3.0, 40.0))
    assert belief.top[0] == "kitchen"
    assert observation.evidence.best is not None
    assert observation.evidence.best.room == "kitchen"
    assert set(observation.timing_ms) == {"extraction", "retrieval", "verification"}


def test_a_repeated_view_sharpens_the_belief(localizer: Localizer):
    image = capture_in("seminar", 3.1, 3.3, -70.0)
    first, _ = localizer.localize_once(image)
    again = localizer.update(localizer.observe(image))
    assert again.top[0] == first.top[0] == "seminar"
    assert again.top[1] >= first.top[1]


def test_reset_with_a_prior_and_prediction_along_the_graph(localizer: Localizer):
    belief = localizer.reset({"kitchen": 1.0})
    assert belief.as_dict()["kitchen"] == 1.0
    localizer.predict()
    spread = localizer.belief().as_dict()
    assert spread["corridor"] > 0  # kitchen's only neighbour
    assert spread["seminar"] == 0


def test_leaving_a_place_out_removes_it_from_the_evidence(localizer: Localizer):
    place = localizer.map.places[0]
    fingerprint = localizer.map.fingerprint(place.id)
    kept = localizer.observe_fingerprint(fingerprint, exclude=place.id)
    assert all(e.place_id != place.id for e in kept.evidence.places)
    full = localizer.observe_fingerprint(fingerprint)
    assert full.evidence.best.place_id == place.id


def test_a_blank_panorama_leaves_the_localizer_lost(localizer: Localizer):
    blank = capture_in("kitchen", 2.0, 3.0, 0.0) * 0 + 128
    belief, _ = localizer.localize_once(blank)
    assert belief.state is LocalizationState.LOST
    assert max(belief.probabilities) == pytest.approx(1 / len(belief.rooms))


def test_a_map_without_the_detector_is_refused_by_name(building_map):
    db_path, _ = building_map
    with pytest.raises(ValueError, match="no place with a 'mser' fingerprint"):
        LoadedMap.from_snapshot(load_snapshot(db_path, detector="mser"))


def test_an_empty_map_is_refused(tmp_path):
    MapDatabase.open(tmp_path / "empty.db").close()
    with pytest.raises(ValueError, match=r"empty\.db has no place"):
        LoadedMap.from_snapshot(load_snapshot(tmp_path / "empty.db"))


def test_images_of_other_shapes_are_refused():
    import numpy as np

    with pytest.raises(ValueError, match=r"\(4, 4, 2\)"):
        to_grey(np.zeros((4, 4, 2), np.uint8))


def test_extraction_threads_must_be_at_least_one():
    from localizer.localizer import LocalizerConfig

    assert LocalizerConfig().extraction_threads == 2  # the query's halves on both cores
    with pytest.raises(ValueError, match="extraction_threads"):
        LocalizerConfig(extraction_threads=0)


def test_a_map_calibrated_before_the_spread_count_is_read_on_raw_inliers(building_map):
    db_path, _ = building_map
    loaded = LoadedMap.from_snapshot(load_snapshot(db_path))
    image = capture_in("kitchen", 2.0, 3.0, 40.0)
    _, observation = Localizer(loaded).localize_once(image)
    raw = max(p.inliers for p in observation.evidence.places)
    spread = max(p.spread_inliers for p in observation.evidence.places)
    assert spread < raw
    # a stored model whose lost threshold lies between the two counts
    stored = replace(loaded.likelihood or RatioLikelihood(), min_inliers=math.ceil(spread) + 1)
    legacy = {k: v for k, v in stored.to_json().items() if k != "count"}
    states = {}
    for name, data in (("legacy", legacy), ("spread", stored.to_json())):
        model = RatioLikelihood.from_json(data)
        belief, _ = Localizer(replace(loaded, likelihood=model)).localize_once(image)
        states[name] = belief.state
    assert states["legacy"] is not LocalizationState.LOST  # raw inliers, above the threshold
    assert states["spread"] is LocalizationState.LOST


def one_and_two_place_map(edges: tuple[tuple[str, str], ...] = ()) -> LoadedMap:
    """``attic`` with one place, ``cellar`` with two (random-texture fingerprints of more than
    100 keypoints each), joined by ``edges``."""
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (96, 384), dtype=np.uint8) for _ in range(3)]
    fingerprints = [extract_with_camera(image, CameraSpec(), "sift") for image in images]
    rooms = ["attic", "cellar", "cellar"]
    table = FingerprintTable.stack("sift", [1, 2, 3], rooms, fingerprints)
    places = tuple(Place(i, room) for i, room in zip([1, 2, 3], rooms, strict=True))
    return LoadedMap.from_snapshot(
        MapSnapshot(Path("m"), table, places, ("attic", "cellar"), edges)
    )


@pytest.mark.parametrize(("top_room", "state"), [("cellar", "localized"), ("attic", "ambiguous")])
def test_a_room_of_one_place_must_win_by_more_to_be_localized(top_room: str, state: str):
    localizer = Localizer(one_and_two_place_map())
    other = "attic" if top_room == "cellar" else "cellar"
    belief = localizer.reset({top_room: 15.0, other: 1.0})  # 15 to 1: between 10 and 20
    assert belief.state is LocalizationState(state)
    assert localizer.map.places_per_room == {"attic": 1, "cellar": 2}


def frame_seeing(
    localizer: Localizer, seen: dict[int, tuple[float, float]], on_place: int | None = None
):
    """An observation whose evidence is, for each place id of ``seen``, 60 inliers on the
    frame's keypoints whose azimuths lie in the arc ``(from_deg, to_deg)`` of the horizon (its
    first 100 keypoints only). The frame is place ``on_place``'s own view, or, if None, a view
    of random texture taken on none of the map's places."""
    from localizer.evidence import PlaceEvidence, QueryEvidence, azimuth_coverage
    from localizer.localizer import Observation

    if on_place is None:
        image = np.random.default_rng(4).integers(0, 256, (96, 384), dtype=np.uint8)
        fingerprint = extract_with_camera(image, CameraSpec(), "sift")
    else:
        fingerprint = localizer.map.fingerprint(on_place)
    rays = fingerprint.rays()
    azimuth_deg = np.degrees(np.arctan2(rays[:100, 1], rays[:100, 0])) % 360.0
    items = []
    for place_id, (from_deg, to_deg) in seen.items():
        rows = np.resize(np.flatnonzero((azimuth_deg >= from_deg) & (azimuth_deg < to_deg)), 60)
        pairs = np.stack([rows, rows], axis=1)
        room = localizer.map.place(place_id).room
        coverage = azimuth_coverage(rays[rows])
        items.append(PlaceEvidence(place_id, room, 80, len(rows), 0.0, pairs, coverage))
    return Observation(fingerprint, QueryEvidence(tuple(items), {}), {})


@pytest.mark.parametrize(("arc_deg", "state"), [(340.0, "localized"), (130.0, "ambiguous")])
def test_a_room_seen_on_part_of_the_horizon_is_not_localized(arc_deg, state):
    localizer = Localizer(one_and_two_place_map())
    localizer.reset({"attic": 100.0, "cellar": 1.0})  # sure enough for a one-place room
    localizer.latest = frame_seeing(localizer, {1: (0.0, arc_deg)})
    assert localizer.belief().state is LocalizationState(state)


def test_a_belief_that_waits_for_a_room_seen_in_part_says_on_how_much_of_the_horizon():
    localizer = Localizer(one_and_two_place_map())
    localizer.reset({"attic": 100.0, "cellar": 1.0})
    localizer.latest = frame_seeing(localizer, {1: (0.0, 130.0)})
    seen = localizer.belief().partly_seen
    assert seen is not None and seen.room == "attic"
    assert seen.horizon_share == pytest.approx(localizer.latest.room_coverages["attic"])
    assert seen.horizon_share < seen.needed_share == localizer.config.thresholds.min_coverage
    localizer.latest = frame_seeing(localizer, {1: (0.0, 340.0)})
    assert localizer.belief().partly_seen is None  # localized: it waits for nothing


def test_a_room_of_two_places_seen_through_its_door_from_both_is_not_localized():
    localizer = Localizer(one_and_two_place_map())
    localizer.reset({"cellar": 100.0, "attic": 1.0})
    localizer.latest = frame_seeing(localizer, {2: (0.0, 100.0), 3: (20.0, 130.0)})
    assert localizer.belief().state is LocalizationState.AMBIGUOUS
    assert localizer.unseen_room() == "cellar"  # the loop homes to one of its places


def test_a_room_whose_places_are_each_seen_on_half_the_horizon_is_seen_all_round():
    localizer = Localizer(one_and_two_place_map())
    localizer.reset({"cellar": 100.0, "attic": 1.0})
    localizer.latest = frame_seeing(localizer, {2: (0.0, 170.0), 3: (180.0, 350.0)})
    assert localizer.belief().state is LocalizationState.LOCALIZED
    assert localizer.unseen_room() is None


@pytest.mark.parametrize(("on_place", "state"), [(2, "localized"), (None, "ambiguous")])
def test_a_frame_on_one_of_a_rooms_places_sees_that_room_enough_on_part_of_the_horizon(
    on_place, state
):
    localizer = Localizer(one_and_two_place_map())
    localizer.reset({"cellar": 100.0, "attic": 1.0})
    localizer.latest = frame_seeing(localizer, {2: (0.0, 130.0)}, on_place=on_place)
    assert localizer.belief().state is LocalizationState(state)


def test_a_frame_on_a_place_of_another_room_does_not_count_as_on_the_likely_rooms_place():
    localizer = Localizer(one_and_two_place_map())
    localizer.reset({"cellar": 100.0, "attic": 1.0})
    localizer.latest = frame_seeing(localizer, {2: (0.0, 130.0), 1: (0.0, 60.0)}, on_place=1)
    assert localizer.belief().state is LocalizationState.AMBIGUOUS


def frame_odds(localizer: Localizer, frame) -> float:
    """How many times more likely ``frame`` is in the cellar than in the attic."""
    likelihood = dict(zip(localizer.map.rooms, localizer.frame_likelihood(frame), strict=True))
    return likelihood["cellar"] / likelihood["attic"]


def test_a_room_seen_through_its_door_is_at_most_the_ratio_likelier_than_the_room_beyond():

    localizer = Localizer(one_and_two_place_map(edges=(("attic", "cellar"),)))
    through_the_door = frame_seeing(localizer, {2: (0.0, 130.0)})
    assert frame_odds(localizer, through_the_door) == pytest.approx(PARTIAL_VIEW_RATIO)


def test_a_room_seen_all_round_is_not_shared_with_the_room_it_opens_onto():

    localizer = Localizer(one_and_two_place_map(edges=(("attic", "cellar"),)))
    inside = frame_seeing(localizer, {2: (0.0, 340.0)})
    assert frame_odds(localizer, inside) > 10 * PARTIAL_VIEW_RATIO


def test_a_room_seen_on_part_of_the_horizon_shares_nothing_with_a_room_it_does_not_open_onto():

    localizer = Localizer(one_and_two_place_map())  # no door between them
    partial = frame_seeing(localizer, {2: (0.0, 130.0)})
    assert frame_odds(localizer, partial) > 10 * PARTIAL_VIEW_RATIO


def test_a_frame_where_the_robot_homed_to_a_rooms_one_place_favours_it_by_at_most_the_cap():
    from dataclasses import replace as with_field

    from localizer.localizer import HOMED_ONE_PLACE_RATIO

    localizer = Localizer(one_and_two_place_map())
    frame = frame_seeing(localizer, {1: (0.0, 340.0)})
    seen = dict(zip(localizer.map.rooms, localizer.frame_likelihood(frame), strict=True))
    homed = with_field(frame, at_place=1)
    held = dict(zip(localizer.map.rooms, localizer.frame_likelihood(homed), strict=True))
    assert seen["attic"] > HOMED_ONE_PLACE_RATIO * seen["cellar"]  # 60 inliers: far more
    assert held["attic"] == pytest.approx(HOMED_ONE_PLACE_RATIO * held["cellar"])


def test_doubting_a_room_takes_back_its_lead_over_the_likeliest_other():
    localizer = Localizer(one_and_two_place_map())
    localizer.reset({"attic": 100.0, "cellar": 1.0})  # what frames said for the attic
    belief = localizer.doubt("attic").as_dict()  # its check did not arrive
    assert belief["attic"] == pytest.approx(belief["cellar"])
    assert localizer.doubt("cellar").as_dict() == pytest.approx(belief)  # no lead: unchanged


def test_a_doubted_room_gains_nothing_from_frames_until_the_belief_starts_afresh():
    localizer = Localizer(one_and_two_place_map())
    frame = frame_seeing(localizer, {1: (0.0, 340.0)})  # 60 inliers with the attic's place
    localizer.doubt("attic")  # its check did not arrive: the frame may be an unknown twin's
    held = dict(zip(localizer.map.rooms, localizer.frame_likelihood(frame), strict=True))
    assert held["attic"] == pytest.approx(held["cellar"])
    before = localizer.belief().as_dict()["attic"]
    assert localizer.update(frame).as_dict()["attic"] == pytest.approx(before)
    localizer.reset()
    seen = dict(zip(localizer.map.rooms, localizer.frame_likelihood(frame), strict=True))
    assert seen["attic"] > 10 * seen["cellar"]


def test_doubting_a_room_the_map_lacks_is_refused_by_name():
    localizer = Localizer(one_and_two_place_map())
    with pytest.raises(ValueError, match="no room 'garage'"):
        localizer.doubt("garage")


def test_a_frame_where_the_robot_homed_to_a_place_of_a_room_of_two_is_read_in_full():
    from dataclasses import replace as with_field

    localizer = Localizer(one_and_two_place_map())
    frame = frame_seeing(localizer, {2: (0.0, 340.0)})
    np.testing.assert_allclose(
        localizer.frame_likelihood(with_field(frame, at_place=2)),
        localizer.frame_likelihood(frame),
    )


def seen_at(localizer: Localizer, x_m: float, y_m: float):
    """The cellar frame of :func:`frame_seeing`, captured at odometry ``(x_m, y_m)``."""
    return replace(frame_seeing(localizer, {2: (0.0, 340.0)}), odometry=Pose2D(x_m, y_m, 0.0))


def test_a_frame_from_the_spot_of_the_latest_replaces_its_evidence():
    localizer = Localizer(one_and_two_place_map())
    once = localizer.update(seen_at(localizer, 0.0, 0.0)).as_dict()
    again = localizer.update(seen_at(localizer, 0.2, 0.1)).as_dict()  # 0.22 m on
    assert again == pytest.approx(once)


def test_a_frame_from_elsewhere_adds_its_evidence_to_the_latest():
    localizer = Localizer(one_and_two_place_map())
    once = localizer.update(seen_at(localizer, 0.0, 0.0)).as_dict()
    twice = localizer.update(seen_at(localizer, 1.0, 0.0)).as_dict()
    assert twice["cellar"] > once["cellar"]
    assert twice["attic"] / twice["cellar"] == pytest.approx((once["attic"] / once["cellar"]) ** 2)


def test_frames_of_unknown_odometry_whose_images_differ_each_add_their_evidence():
    localizer = Localizer(one_and_two_place_map())
    frame = frame_seeing(localizer, {2: (0.0, 340.0)})
    other_view = replace(frame, fingerprint=localizer.map.fingerprint(3))
    once = localizer.update(frame).as_dict()
    twice = localizer.update(other_view).as_dict()
    assert twice["attic"] / twice["cellar"] == pytest.approx((once["attic"] / once["cellar"]) ** 2)


def test_a_frame_of_unknown_odometry_whose_image_repeats_the_latest_replaces_its_evidence():
    localizer = Localizer(one_and_two_place_map())
    frame = frame_seeing(localizer, {2: (0.0, 340.0)})
    once = localizer.update(frame).as_dict()
    again = localizer.update(frame).as_dict()  # a camera alone, asked twice
    assert again == pytest.approx(once)


def test_frames_of_one_view_are_compared_with_its_first_frame():
    localizer = Localizer(one_and_two_place_map())
    once = localizer.update(seen_at(localizer, 0.0, 0.0)).as_dict()
    localizer.update(seen_at(localizer, 0.25, 0.0))  # the same view
    then = localizer.update(seen_at(localizer, 0.5, 0.0)).as_dict()  # 0.25 m on, 0.5 m from it
    assert then["attic"] / then["cellar"] == pytest.approx((once["attic"] / once["cellar"]) ** 2)


def test_a_passive_frame_of_a_new_view_is_folded_in_after_the_belief_is_spread():
    localizer = Localizer(one_and_two_place_map())  # two rooms, no doors
    once = localizer.update(seen_at(localizer, 0.0, 0.0), passive=True).as_dict()
    then = localizer.update(seen_at(localizer, 1.0, 0.0), passive=True).as_dict()
    share = localizer.config.passive_anywhere_probability / 2
    spread = {room: (1 - 2 * share) * p + share for room, p in once.items()}
    expected = (spread["attic"] / spread["cellar"]) * (once["attic"] / once["cellar"])
    assert then["attic"] / then["cellar"] == pytest.approx(expected)


def test_a_passive_frame_of_the_latest_view_replaces_its_evidence_unspread():
    localizer = Localizer(one_and_two_place_map())
    once = localizer.update(seen_at(localizer, 0.0, 0.0), passive=True).as_dict()
    again = localizer.update(seen_at(localizer, 0.1, 0.0), passive=True).as_dict()
    assert again == pytest.approx(once)


def test_after_a_check_is_folded_in_a_frame_from_the_same_spot_adds_its_evidence():
    localizer = Localizer(one_and_two_place_map())
    localizer.update(seen_at(localizer, 0.0, 0.0))
    checked = localizer.update_rooms({"cellar": 3.0}).as_dict()
    then = localizer.update(seen_at(localizer, 0.0, 0.0)).as_dict()
    assert then["cellar"] > checked["cellar"]


def twin_offices_map() -> LoadedMap:
    """office_a's places 1 and 2, office_b's 3 and 4: 1 and 3 on one spot of the twins'
    frames (one view), 2 and 4 counterparts that stand apart (two views)."""
    rng = np.random.default_rng(1)
    images = [rng.integers(0, 256, (64, 256), dtype=np.uint8) for _ in range(3)]
    fingerprints = [extract_with_camera(images[i], CameraSpec(), "sift") for i in (0, 1, 0, 2)]
    rooms = ["office_a", "office_a", "office_b", "office_b"]
    table = FingerprintTable.stack("sift", [1, 2, 3, 4], rooms, fingerprints)
    places = tuple(Place(i, room) for i, room in zip([1, 2, 3, 4], rooms, strict=True))
    model = RatioLikelihood(
        lookalikes=(("office_a", "office_b"),), counterparts=((1, 3), (2, 4))
    ).to_json()
    snapshot = MapSnapshot(Path("m"), table, places, ("office_a", "office_b"), (), model)
    return LoadedMap.from_snapshot(snapshot)


def frame_on(localizer: Localizer, counts: dict[int, int], at_place: int | None = None):
    """An observation whose evidence is ``counts`` (place id: inliers, over the horizon)."""
    from localizer.evidence import PlaceEvidence, QueryEvidence
    from localizer.localizer import Observation

    items = tuple(
        PlaceEvidence(i, localizer.map.place(i).room, n, n, 0.0, np.zeros((n, 2), np.int64), 1.0)
        for i, n in counts.items()
    )
    return Observation(localizer.map.fingerprint(1), QueryEvidence(items, {}), {}, at_place)


def test_twins_are_read_on_counterparts_on_one_spot_wherever_the_frame_was_taken():
    localizer = Localizer(twin_offices_map())
    a, b = localizer.frame_likelihood(frame_on(localizer, {1: 60, 3: 120}))
    assert b > 2 * a


def test_counterparts_that_stand_apart_are_not_read_from_elsewhere():
    # 4 stands nearer the robot than 2 does: that says nothing about which office it is in
    localizer = Localizer(twin_offices_map())
    a, b = localizer.frame_likelihood(frame_on(localizer, {2: 60, 4: 120}))
    assert a == pytest.approx(b)


def test_counterparts_that_stand_apart_are_read_where_the_robot_homed_to_one():
    # homed to office_a's 2, yet office_b's 4 explains the frame better: against the offset
    localizer = Localizer(twin_offices_map())
    a, b = localizer.frame_likelihood(frame_on(localizer, {2: 60, 4: 120}, at_place=2))
    assert b > 2 * a


def office_twins_and_storage_map() -> LoadedMap:
    """Places 1 (office_a), 2 (office_b), 3 (storage); office_a looks like office_b and like
    storage (a wall of photographs they share), office_b not like storage: one group."""
    rng = np.random.default_rng(2)
    images = [rng.integers(0, 256, (64, 256), dtype=np.uint8) for _ in range(3)]
    fingerprints = [extract_with_camera(image, CameraSpec(), "sift") for image in images]
    rooms = ["office_a", "office_b", "storage"]
    table = FingerprintTable.stack("sift", [1, 2, 3], rooms, fingerprints)
    places = tuple(Place(i, room) for i, room in zip([1, 2, 3], rooms, strict=True))
    pairs = (("office_a", "office_b"), ("office_a", "storage"))
    model = RatioLikelihood(lookalikes=pairs).to_json()
    snapshot = MapSnapshot(Path("m"), table, places, tuple(rooms), (), model)
    return LoadedMap.from_snapshot(snapshot)


def test_a_room_is_as_likely_as_its_own_look_alikes_show_not_as_its_group():
    # the robot stands where office_b's place stood, in office_a or office_b: the storage room,
    # which looks like office_a only, gains only what office_a's count gives it
    localizer = Localizer(office_twins_and_storage_map())
    assert localizer.lookalike_groups == ((0, 1, 2),)
    a, b, storage = localizer.frame_likelihood(frame_on(localizer, {1: 25, 2: 326, 3: 1}))
    assert a == pytest.approx(b)
    log_ratio = localizer.likelihood.log_ratio(np.array([25.0, 326.0]))
    assert storage / a == pytest.approx(math.exp(log_ratio[0] - log_ratio[1]))
    assert storage < a / 100
