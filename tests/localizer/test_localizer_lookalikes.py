"""Look-alike rooms: their groups, counterparts, and how a frame's counts weigh them."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from localizer.likelihood import (
    MAX_TWIN_LOG_RATIO,
    RatioLikelihood,
    lookalike_log_ratios,
    room_inliers,
)
from localizer.lookalikes import (
    is_counterpart,
    lookalike_groups,
    pairs_without_counterparts,
    partners_of,
    twin_counts,
)

ROOMS = ("corridor", "office_a", "office_b", "kitchen", "bedroom_a", "bedroom_b")
OFFICES = ((1, 2),)


@dataclass(frozen=True)
class Score:
    """A place's evidence as the likelihood reads it."""

    place_id: int
    room: str
    inliers: int

    @property
    def spread_inliers(self) -> float:
        return float(self.inliers)


def test_look_alike_pairs_join_into_groups_of_room_indices():
    pairs = [("office_a", "office_b"), ("bedroom_b", "bedroom_a")]
    assert lookalike_groups(pairs, ROOMS) == ((1, 2), (4, 5))


def test_a_pair_naming_a_room_the_map_lacks_is_left_out():
    assert lookalike_groups([("office_a", "lab")], ROOMS) == ()


def test_pairs_that_share_a_room_make_one_group():
    pairs = [("office_a", "office_b"), ("office_b", "kitchen")]
    assert lookalike_groups(pairs, ROOMS) == ((1, 2, 3),)


def test_places_at_the_same_spot_of_twin_rooms_are_counterparts():
    assert is_counterpart(820, 1000)  # the batch map's twin offices: 0.80-0.94 of the keypoints
    assert not is_counterpart(200, 1000)  # recorded maps' twin places: at most 0.22
    assert not is_counterpart(0, 0)


def test_aliased_twins_are_equally_likely_whatever_their_counts():
    # office_b's stored place is nearer the robot: 183 against 96 inliers
    model = RatioLikelihood()
    counts = np.array([5.0, 96.0, 183.0, 0.0, 0.0, 0.0])
    aliased = model.from_counts(counts, OFFICES)
    plain = model.from_counts(counts)
    assert aliased[1] == pytest.approx(aliased[2])
    assert plain[2] / plain[1] > 50  # what the counts alone said: localized in office_b


def test_a_room_outside_the_group_keeps_its_odds_against_either_twin():
    model = RatioLikelihood()
    counts = np.array([150.0, 96.0, 183.0, 0.0, 0.0, 0.0])
    aliased = model.from_counts(counts, OFFICES)
    plain = model.from_counts(counts)
    assert aliased[0] / aliased[1] == pytest.approx(plain[0] / plain[2], rel=1e-9)
    assert aliased[0] / aliased[2] == pytest.approx(plain[0] / plain[2], rel=1e-9)


@given(logs=st.lists(st.floats(-25, 25), min_size=4, max_size=4))
def test_an_aliased_group_is_as_likely_as_its_best_room_and_no_more(logs):
    out = lookalike_log_ratios(np.array(logs), ((0, 2, 3),))
    assert out[0] == out[2] == out[3] == max(logs[0], logs[2], logs[3])
    assert out[1] == logs[1]


def test_a_room_is_lifted_by_its_own_look_alikes_not_by_theirs():
    # office_a ~ office_b (twins) and office_a ~ kitchen (photos on a shared wall): one group,
    # but the kitchen does not look like what office_b's place shows
    model = RatioLikelihood()
    raw = model.log_ratio(np.array([0.0, 25.0, 326.0, 1.0, 0.0, 0.0]))
    pairs = [(1, 2), (1, 3)]
    out = lookalike_log_ratios(raw, ((1, 2, 3),), pairs=pairs)
    assert out[1] == out[2] == raw[2]  # the twins: as likely as the twin that shows most
    assert out[3] == raw[1]  # the kitchen: as likely as office_a, its look-alike, shows
    assert out[2] - out[3] > math.log(100)


@given(logs=st.lists(st.floats(-25, 25), min_size=4, max_size=4))
def test_a_group_whose_rooms_are_all_look_alikes_is_at_its_best_rooms(logs):
    pairs = [(0, 2), (0, 3), (2, 3)]
    assert list(lookalike_log_ratios(np.array(logs), ((0, 2, 3),), pairs=pairs)) == list(
        lookalike_log_ratios(np.array(logs), ((0, 2, 3),))
    )


def test_twins_are_read_on_the_counterpart_pair_the_frame_verified():
    # the robot is nearest office_b's place 12, which has no counterpart; office_a's 3 and
    # office_b's 13 stand at one spot of their frames and the frame verified both
    evidence = [Score(12, "office_b", 183), Score(3, "office_a", 120), Score(13, "office_b", 90)]
    counts = room_inliers(evidence, ROOMS, count="inliers")
    read, aliased = twin_counts(
        evidence, ROOMS, counts, OFFICES, partners_of([(3, 13)]), count="inliers"
    )
    assert aliased == ()
    assert read[1] == 120 and read[2] == 90


def test_twins_without_a_verified_counterpart_pair_stay_aliased():
    evidence = [Score(12, "office_b", 183), Score(3, "office_a", 120)]
    counts = room_inliers(evidence, ROOMS, count="inliers")
    # 3's counterpart 13 was not among the places the frame verified
    read, aliased = twin_counts(
        evidence, ROOMS, counts, OFFICES, partners_of([(3, 13)]), count="inliers"
    )
    assert aliased == OFFICES
    assert list(read) == list(counts)


def test_of_several_counterpart_pairs_the_best_matched_is_read():
    evidence = [
        Score(3, "office_a", 60),
        Score(13, "office_b", 70),
        Score(4, "office_a", 150),
        Score(14, "office_b", 110),
    ]
    counts = room_inliers(evidence, ROOMS, count="inliers")
    pairs = [(3, 13), (4, 14)]
    read, _ = twin_counts(evidence, ROOMS, counts, OFFICES, partners_of(pairs), count="inliers")
    assert read[1] == 150 and read[2] == 110


def test_look_alikes_and_counterparts_survive_the_map_round_trip():
    model = RatioLikelihood(lookalikes=(("office_a", "office_b"),), counterparts=((3, 13),))
    assert RatioLikelihood.from_json(model.to_json()) == model


def test_a_model_stored_before_look_alikes_has_none():
    stored = RatioLikelihood().to_json()
    del stored["lookalikes"], stored["counterparts"]
    model = RatioLikelihood.from_json(stored)
    assert model.lookalikes == () and model.counterparts == ()


def test_look_alike_pairs_no_counterpart_joins_are_the_blind_ones():
    room_of = {3: "office_a", 13: "office_b", 30: "bedroom_a", 31: "bedroom_b"}
    pairs = [("office_a", "office_b"), ("bedroom_a", "bedroom_b")]
    assert pairs_without_counterparts(pairs, [(3, 13)], room_of) == (("bedroom_a", "bedroom_b"),)


def test_a_frame_at_the_place_driven_to_is_not_read_on_that_place_when_it_wins():
    # homed to office_a's 3: its count beats its counterpart's by how far 13 stands off the spot
    evidence = [Score(3, "office_a", 150), Score(13, "office_b", 90)]
    counts = room_inliers(evidence, ROOMS, count="inliers")
    _, aliased = twin_counts(
        evidence, ROOMS, counts, OFFICES, partners_of([(3, 13)]), count="inliers", at_place=3
    )
    assert aliased == OFFICES


def test_a_frame_at_the_place_driven_to_is_read_on_its_pair_when_the_counterpart_wins():
    # homed to office_a's 3, yet office_b's 13 explains the frame better: against the offset
    evidence = [Score(3, "office_a", 90), Score(13, "office_b", 150)]
    counts = room_inliers(evidence, ROOMS, count="inliers")
    read, aliased = twin_counts(
        evidence, ROOMS, counts, OFFICES, partners_of([(3, 13)]), count="inliers", at_place=3
    )
    assert aliased == () and (read[1], read[2]) == (90, 150)


def test_a_frame_at_the_place_driven_to_is_read_on_the_other_pairs():
    evidence = [
        Score(3, "office_a", 150),
        Score(13, "office_b", 90),
        Score(4, "office_a", 60),
        Score(14, "office_b", 70),
    ]
    counts = room_inliers(evidence, ROOMS, count="inliers")
    pairs = [(3, 13), (4, 14)]
    read, aliased = twin_counts(
        evidence, ROOMS, counts, OFFICES, partners_of(pairs), count="inliers", at_place=3
    )
    assert aliased == () and (read[1], read[2]) == (60, 70)


def test_one_frame_read_on_counterparts_moves_twins_by_at_most_the_cap():
    model = RatioLikelihood()
    counts = np.array([5.0, 300.0, 120.0, 0.0, 0.0, 0.0])
    likelihood = model.from_counts(counts, compared=OFFICES)
    assert likelihood[1] / likelihood[2] == pytest.approx(math.exp(MAX_TWIN_LOG_RATIO))


def test_a_room_seen_through_a_door_from_a_few_views_is_no_look_alike():
    from localizer.likelihood_fit import CalibrationSamples

    sizes = {"hall": 3, "bedroom_a": 2, "bedroom_b": 2}
    queries = [
        ("hall", {"hall": 100.0, "bedroom_a": 90.0}),  # at the bedroom's door
        ("hall", {"hall": 100.0, "bedroom_a": 5.0}),
        ("hall", {"hall": 100.0, "bedroom_a": 4.0}),
        ("bedroom_a", {"bedroom_a": 60.0, "bedroom_b": 70.0, "hall": 50.0}),
        ("bedroom_a", {"bedroom_a": 60.0, "bedroom_b": 65.0}),
        ("bedroom_b", {"bedroom_b": 60.0, "bedroom_a": 75.0}),
        ("bedroom_b", {"bedroom_b": 60.0, "bedroom_a": 62.0}),
    ]
    samples = CalibrationSamples.from_queries(queries, sizes)
    assert samples.lookalike_pairs == (("bedroom_a", "bedroom_b"),)


def test_rooms_joined_by_a_door_that_see_each_other_in_half_their_views_are_no_look_alikes():
    from localizer.likelihood_fit import CalibrationSamples

    # the bare house recorded on one drive, two places per room (world seed 17): one hall
    # place stands by bathroom_a's door and one bathroom place looks out through it; each
    # room finds the other in half of its views, as its twin would
    sizes = {"hall": 2, "bathroom_a": 2, "bathroom_b": 2, "study": 2}
    queries = [
        ("hall", {"hall": 30.0, "bathroom_a": 28.0, "study": 1.0}),
        ("hall", {"hall": 40.0, "bathroom_a": 2.0, "study": 1.0}),
        ("bathroom_a", {"bathroom_a": 20.0, "hall": 25.0, "bathroom_b": 3.0}),
        ("bathroom_a", {"bathroom_a": 20.0, "hall": 3.0, "bathroom_b": 15.0}),
        ("bathroom_b", {"bathroom_b": 20.0, "bathroom_a": 17.0, "hall": 2.0}),
        ("bathroom_b", {"bathroom_b": 22.0, "bathroom_a": 19.0, "study": 1.0}),
    ]
    edges = [("hall", "bathroom_a"), ("hall", "bathroom_b"), ("hall", "study")]
    through_doors = CalibrationSamples.from_queries(queries, sizes, edges=edges)
    assert through_doors.lookalike_pairs == (("bathroom_a", "bathroom_b"),)
    without_doors = CalibrationSamples.from_queries(queries, sizes)
    assert ("bathroom_a", "hall") in without_doors.lookalike_pairs


def test_twins_recorded_a_metre_apart_are_look_alikes_though_each_room_wins_its_own_views():
    from localizer.likelihood_fit import CalibrationSamples

    # a map recorded with three places per office (world seed 2): the own office wins most
    # views, the twin explains all of them at 0.5-0.9 of that, every other room by chance
    sizes = {"office_a": 3, "office_b": 3, "kitchen": 3}
    queries = [
        ("office_a", {"office_a": 174.0, "office_b": 179.0, "kitchen": 13.0}),
        ("office_a", {"office_a": 212.0, "office_b": 137.0, "kitchen": 10.0}),
        ("office_a", {"office_a": 209.0, "office_b": 110.0}),
        ("office_b", {"office_b": 41.0, "office_a": 95.0}),
        ("office_b", {"office_b": 217.0, "office_a": 158.0, "kitchen": 12.0}),
        ("office_b", {"office_b": 209.0, "office_a": 188.0}),
        ("kitchen", {"kitchen": 150.0, "office_a": 12.0}),
    ]
    samples = CalibrationSamples.from_queries(queries, sizes)
    assert samples.lookalike_pairs == (("office_a", "office_b"),)


def test_a_twin_far_above_chance_in_every_view_is_a_look_alike_at_a_fifth_of_the_count():
    from localizer.likelihood_fit import CalibrationSamples

    # a map recorded with three places per office (world seed 9): each office wins its own
    # views by four to six times, the twin stands at 14-31, every room but the corridor at 0-5
    sizes = {"corridor": 3, "kitchen": 3, "office_a": 3, "office_b": 3, "seminar": 3}
    queries = [
        ("office_a", {"corridor": 4, "kitchen": 1, "office_a": 113, "office_b": 21, "seminar": 3}),
        ("office_a", {"corridor": 4, "kitchen": 1, "office_a": 113, "office_b": 25, "seminar": 2}),
        ("office_a", {"corridor": 3, "office_a": 96, "office_b": 14, "seminar": 1}),
        ("office_b", {"corridor": 2, "kitchen": 2, "office_a": 31, "office_b": 88, "seminar": 2}),
        ("office_b", {"corridor": 2, "kitchen": 1, "office_a": 16, "office_b": 88, "seminar": 2}),
        ("office_b", {"corridor": 24, "kitchen": 5, "office_a": 8, "office_b": 47, "seminar": 1}),
    ]
    edges = [("corridor", "office_a"), ("corridor", "office_b"), ("corridor", "kitchen")]
    samples = CalibrationSamples.from_queries(queries, sizes, edges=edges)
    assert samples.lookalike_pairs == (("office_a", "office_b"),)
    assert samples.pair_tests == ("standout",)


def test_a_room_at_a_few_percent_of_the_own_count_is_no_look_alike_however_far_above_chance():
    from localizer.likelihood_fit import CalibrationSamples

    sizes = {"kitchen": 3, "office_a": 3, "seminar": 3}
    queries = [
        ("kitchen", {"kitchen": 150.0, "office_a": 12.0, "seminar": 1.0}),
        ("kitchen", {"kitchen": 140.0, "office_a": 11.0, "seminar": 2.0}),
        ("office_a", {"office_a": 120.0, "kitchen": 3.0, "seminar": 2.0}),
    ]
    assert CalibrationSamples.from_queries(queries, sizes).lookalike_pairs == ()


def test_a_room_no_query_came_from_is_no_look_alike_but_is_named_to_ask():
    from localizer.likelihood_fit import CalibrationSamples

    sizes = {"office_a": 3, "office_b": 3, "kitchen": 3}
    queries = [
        ("office_a", {"office_a": 200.0, "office_b": 180.0}),
        ("kitchen", {"kitchen": 150.0, "office_a": 12.0}),
    ]
    samples = CalibrationSamples.from_queries(queries, sizes)
    assert samples.lookalike_pairs == ()
    assert samples.unasked_lookalikes == ("office_b",)


def test_bare_twins_at_a_few_inliers_are_look_alikes_when_every_other_room_is_chance():
    from localizer.likelihood_fit import CalibrationSamples

    # the bare house recorded three places per room (world seed 0): the twin bedrooms explain
    # each other's views at 8-50 spread inliers, their own rooms at 6-21, the rest at 0-2
    sizes = {"bedroom_a": 3, "bedroom_b": 3, "study": 3, "hall": 3}
    queries = [
        ("bedroom_a", {"bedroom_b": 14.0, "bedroom_a": 14.0, "study": 2.0}),
        ("bedroom_a", {"bedroom_b": 50.0, "bedroom_a": 13.0, "study": 1.0}),
        ("bedroom_a", {"bedroom_a": 6.0, "bedroom_b": 2.0, "hall": 1.0}),
        ("bedroom_b", {"bedroom_b": 21.0, "bedroom_a": 13.0}),
        ("bedroom_b", {"bedroom_b": 21.0, "bedroom_a": 8.0, "study": 1.0}),
        ("bedroom_b", {"bedroom_a": 48.0, "bedroom_b": 17.0, "hall": 1.0}),
        ("study", {"study": 70.0, "hall": 2.0}),
    ]
    samples = CalibrationSamples.from_queries(queries, sizes)
    assert samples.lookalike_pairs == (("bedroom_a", "bedroom_b"),)


def test_a_few_inliers_above_a_high_chance_level_make_no_look_alike():
    from localizer.likelihood_fit import CalibrationSamples

    # shared texture lifts every room of these views to 5-9: 9 is no twin
    sizes = {"a": 2, "b": 2, "c": 2, "d": 2}
    queries = [
        ("a", {"a": 12.0, "b": 9.0, "c": 7.0, "d": 6.0}),
        ("b", {"b": 12.0, "a": 9.0, "c": 6.0, "d": 5.0}),
    ]
    assert CalibrationSamples.from_queries(queries, sizes).lookalike_pairs == ()


def test_rooms_alike_by_appearance_in_half_the_views_each_are_look_alikes():
    from localizer.likelihood_fit import CalibrationSamples

    # one place per office, a metre apart in their frames: 20-23 inliers is not enough for
    # the count, but each view found the other office alike by its descriptors
    sizes = {"office_a": 1, "office_b": 1, "kitchen": 1}
    queries = [
        ("office_a", {"office_b": 6.0, "kitchen": 2.0}),
        ("office_b", {"office_a": 5.0, "kitchen": 2.0}),
        ("kitchen", {"office_a": 3.0}),
    ]
    alike = [{"office_b"}, {"office_a"}, set()]
    samples = CalibrationSamples.from_queries(queries, sizes, alike=alike)
    assert samples.lookalike_pairs == (("office_a", "office_b"),)
    # and the twins' counts are no chance samples: only the kitchen's and its views' are
    assert sorted(samples.other_room) == [0.0, 2.0, 2.0, 3.0]


def test_each_look_alike_pair_says_which_test_found_it():
    from localizer.likelihood_fit import CalibrationSamples

    # offices found by appearance only (one place each, few inliers, the kitchen near them);
    # bedrooms by their counts (each explains the other's views far above chance); bathrooms
    # named by the user
    sizes = dict.fromkeys(["office_a", "office_b", "kitchen"], 1)
    sizes |= dict.fromkeys(["bed_1", "bed_2", "bath_1", "bath_2"], 2)
    queries = [
        ("office_a", {"office_b": 6.0, "kitchen": 4.0}),
        ("office_b", {"office_a": 5.0, "kitchen": 4.0}),
        ("bed_1", {"bed_1": 30.0, "bed_2": 25.0}),
        ("bed_2", {"bed_2": 28.0, "bed_1": 24.0}),
        ("bath_1", {"bath_1": 30.0}),
    ]
    alike = [{"office_b"}, {"office_a"}, {"bed_2"}, set(), set()]
    samples = CalibrationSamples.from_queries(
        queries, sizes, alike=alike, declared=[("bath_2", "bath_1")]
    )
    assert dict(zip(samples.lookalike_pairs, samples.pair_tests, strict=True)) == {
        ("bath_1", "bath_2"): "declared",
        ("bed_1", "bed_2"): "count",
        ("office_a", "office_b"): "appearance",
    }


def test_a_room_that_outdoes_a_rooms_own_places_is_its_look_alike_from_one_side():
    from localizer.likelihood_fit import CalibrationSamples

    # a recorded house: bedroom_b explains bedroom_a's views as well as bedroom_a does, while
    # bedroom_b's own places stand near each other and find bedroom_a far below themselves
    sizes = dict.fromkeys(["bedroom_a", "bedroom_b", "hall", "study", "kitchen", "bath"], 2)
    queries = [
        ("bedroom_a", {"bedroom_a": 5.0, "bedroom_b": 9.0, "hall": 3.0, "study": 2.0}),
        ("bedroom_a", {"bedroom_a": 5.0, "bedroom_b": 5.0, "study": 2.0}),
        ("bedroom_b", {"bedroom_b": 40.0, "bedroom_a": 11.0, "hall": 2.0}),
        ("bedroom_b", {"bedroom_b": 34.0, "bedroom_a": 4.0, "hall": 2.0}),
    ]
    samples = CalibrationSamples.from_queries(queries, sizes)
    assert samples.lookalike_pairs == (("bedroom_a", "bedroom_b"),)
    assert samples.pair_tests == ("outdone",)


def test_a_room_seen_through_a_door_that_outdoes_the_own_room_is_no_look_alike():
    from localizer.likelihood_fit import CalibrationSamples

    # a bedroom's views near its door see the hall better than the bedroom's other place
    sizes = dict.fromkeys(["bedroom_a", "hall", "study", "kitchen", "bath"], 2)
    queries = [
        ("bedroom_a", {"bedroom_a": 9.0, "hall": 14.0, "study": 2.0, "kitchen": 1.0}),
        ("hall", {"hall": 40.0, "bedroom_a": 3.0, "study": 2.0}),
    ]
    doors = [("bedroom_a", "hall")]
    assert CalibrationSamples.from_queries(queries, sizes, edges=doors).lookalike_pairs == ()
    assert CalibrationSamples.from_queries(queries, sizes).lookalike_pairs == (
        ("bedroom_a", "hall"),
    )


def test_a_room_found_alike_from_one_side_only_is_no_look_alike():
    from localizer.likelihood_fit import CalibrationSamples

    sizes = {"office_a": 1, "office_b": 1, "kitchen": 1}
    queries = [
        ("office_a", {"office_b": 6.0, "kitchen": 4.0}),
        ("office_b", {"office_a": 5.0, "kitchen": 4.0}),
    ]
    samples = CalibrationSamples.from_queries(queries, sizes, alike=[{"office_b"}, set()])
    assert samples.lookalike_pairs == ()


def test_a_twin_matched_often_and_verified_little_looks_alike():
    from localizer.lookalikes import alike_by_appearance

    # (matches, inliers) of each room's best-matching place for a view of office_a
    matches = {"office_b": (99, 30), "storage": (26, 3), "corridor": (22, 2), "kitchen": (19, 1)}
    sizes = {"office_a": 1, "office_b": 1, "storage": 1, "corridor": 1, "kitchen": 1}
    assert alike_by_appearance("office_a", matches, sizes) == {"office_b"}


def test_a_bare_twin_of_one_place_looks_alike_at_twice_what_other_rooms_match():
    from localizer.lookalikes import alike_by_appearance

    # bathroom_b's view on a bare house recorded with one place per room (world seed 26): its
    # twin matches it best, at 40 (7 verified); the other rooms match it at 7-19 by chance
    matches = {"bathroom_a": (40, 7), "bedroom_a": (11, 6), "bedroom_b": (16, 6), "hall": (7, 0)}
    matches |= {"kitchen": (17, 6), "living": (19, 7), "study": (17, 9)}
    sizes = dict.fromkeys([*matches, "bathroom_b"], 1)
    edges = [("hall", "bathroom_b")]
    assert alike_by_appearance("bathroom_b", matches, sizes, edges) == {"bathroom_a"}


def test_a_room_sharing_a_wallpaper_with_a_twin_needs_more_than_twice_the_chance_level():
    from localizer.lookalikes import alike_by_appearance

    # office_b's view, two places per office (world seed 27): the kitchen shares photographs
    # with the offices, matched often and verified never, but its twin matches the view best
    matches = {"office_b": (120, 90), "office_a": (166, 117), "kitchen": (63, 1)}
    matches |= {"corridor": (18, 3), "seminar": (21, 7), "storage": (30, 3)}
    sizes = dict.fromkeys(matches, 2)
    assert alike_by_appearance("office_b", matches, sizes) == frozenset()
    matches["office_a"] = (40, 30)  # were the kitchen the best match, it would be the twin
    assert alike_by_appearance("office_b", matches, sizes) == {"kitchen"}


def test_a_room_sharing_a_few_objects_with_a_twin_of_one_place_does_not_look_alike():
    from localizer.lookalikes import alike_by_appearance

    # office_b's view, one place per room: its twin matches it at 98, the kitchen (a few of the
    # same pictures on its walls) at 42, far above every other room, yet far below the twin
    matches = {"office_a": (98, 46), "kitchen": (42, 7), "corridor": (18, 5), "seminar": (9, 0)}
    matches |= {"storage": (7, 0)}
    sizes = dict.fromkeys(["office_a", "office_b", "kitchen", "corridor", "seminar", "storage"], 1)
    assert alike_by_appearance("office_b", matches, sizes) == {"office_a"}
    alone = {room: counts for room, counts in matches.items() if room != "office_a"}
    assert alike_by_appearance("office_b", alone, sizes) == {"kitchen"}


def test_a_room_seen_through_an_opening_is_matched_and_verified_so_it_does_not_look_alike():
    from localizer.lookalikes import alike_by_appearance

    # a view of the living room; a bedroom's places see the living room through their door
    matches = {"living": (148, 116), "bedroom_a": (136, 100), "hall": (128, 47), "study": (54, 16)}
    sizes = {"living": 8, "bedroom_a": 3, "hall": 9, "study": 3}
    assert alike_by_appearance("living", matches, sizes) == frozenset()


def test_rooms_joined_by_a_door_never_look_alike_by_appearance():
    from localizer.lookalikes import alike_by_appearance

    matches = {"seminar": (67, 20), "office_a": (25, 2), "kitchen": (17, 1), "storage": (14, 1)}
    sizes = {"corridor": 1, "seminar": 1, "office_a": 1, "kitchen": 1, "storage": 1}
    assert alike_by_appearance("corridor", matches, sizes) == {"seminar"}
    edges = [("corridor", "seminar")]
    assert alike_by_appearance("corridor", matches, sizes, edges) == frozenset()


def test_a_room_below_half_the_own_rooms_matches_does_not_look_alike():
    from localizer.lookalikes import alike_by_appearance

    matches = {"hall": (119, 80), "bedroom_a": (24, 4), "kitchen": (22, 3), "study": (21, 3)}
    sizes = {"hall": 3, "bedroom_a": 3, "kitchen": 3, "study": 3}
    assert alike_by_appearance("hall", matches, sizes) == frozenset()


def test_declared_look_alikes_are_a_pair_whatever_the_views_say():
    from localizer.likelihood_fit import CalibrationSamples

    sizes = {"office_a": 2, "office_b": 2, "kitchen": 2}
    queries = [
        ("office_a", {"office_a": 150.0, "office_b": 9.0, "kitchen": 3.0}),
        ("office_b", {"office_b": 140.0, "office_a": 4.0, "kitchen": 2.0}),
    ]
    assert CalibrationSamples.from_queries(queries, sizes).lookalike_pairs == ()
    told = CalibrationSamples.from_queries(queries, sizes, declared=[("office_b", "office_a")])
    assert told.lookalike_pairs == (("office_a", "office_b"),)
    assert sorted(told.other_room) == [2.0, 3.0]  # the twins' counts are no chance samples


# a bare recorded house, three places per room: bedroom_b's views find bedroom_a below half
# their own room's counts, yet far above every other room; bedroom_a's views find bedroom_b once
BEDROOMS = [
    ("bedroom_a", {"bedroom_b": 15.0, "bedroom_a": 2.7, "hall": 1.3, "study": 0.3}),
    ("bedroom_a", {"bedroom_a": 10.0, "bedroom_b": 2.9, "hall": 0.6, "study": 0.1}),
    ("bedroom_a", {"bedroom_a": 7.5, "bath": 2.4, "bedroom_b": 2.2, "hall": 0.8}),
    ("bedroom_b", {"bedroom_b": 24.7, "bedroom_a": 11.7, "living": 0.6}),
    ("bedroom_b", {"bedroom_b": 22.8, "bedroom_a": 12.1, "study": 1.4, "hall": 1.3}),
    ("bedroom_b", {"bedroom_b": 14.4, "bedroom_a": 4.2, "kitchen": 2.3, "hall": 1.4}),
]
HOUSE = dict.fromkeys(["bedroom_a", "bedroom_b", "hall", "living", "kitchen", "study", "bath"], 3)


def test_a_room_that_stands_out_of_every_other_room_in_a_rooms_views_is_its_look_alike():
    from localizer.likelihood_fit import CalibrationSamples

    samples = CalibrationSamples.from_queries(BEDROOMS, HOUSE)
    assert samples.lookalike_pairs == (("bedroom_a", "bedroom_b"),)
    assert samples.pair_tests == ("standout",)


def test_rooms_joined_by_a_door_never_stand_out_as_look_alikes():
    from localizer.likelihood_fit import CalibrationSamples

    doors = [("bedroom_a", "bedroom_b")]
    assert CalibrationSamples.from_queries(BEDROOMS, HOUSE, edges=doors).lookalike_pairs == ()


def test_a_room_level_with_another_room_does_not_stand_out():
    from localizer.likelihood_fit import CalibrationSamples

    # the same views with the kitchen as high as the twin in each: shared texture, not a twin
    level = [(room, counts | {"kitchen": counts[t]}) for (room, counts), t in zip(
        BEDROOMS, ["bedroom_b"] * 3 + ["bedroom_a"] * 3, strict=True
    )]  # fmt: skip
    assert CalibrationSamples.from_queries(level, HOUSE).lookalike_pairs == ()


def test_a_room_standing_out_in_fewer_than_half_of_a_rooms_views_is_no_look_alike():
    from localizer.likelihood_fit import CalibrationSamples

    only_a = [(room, counts) for room, counts in BEDROOMS if room == "bedroom_a"]
    assert CalibrationSamples.from_queries(only_a, HOUSE).lookalike_pairs == ()


# a house recorded on one drive, one place per room (world seed 19): each bedroom's view finds
# the other far above every other room, below the mutual count test's 8 spread inliers once
ONE_PLACE_BEDROOMS = [
    ("bedroom_a", {"bedroom_b": 12.7, "hall": 0.9, "study": 0.8, "living": 0.2}),
    ("bedroom_b", {"bedroom_a": 7.95, "study": 0.9, "living": 0.7, "hall": 0.6}),
    ("hall", {"bedroom_a": 0.5, "bedroom_b": 0.6, "study": 0.2, "living": 0.8}),
]
ONE_PLACE_HOUSE = dict.fromkeys(["bedroom_a", "bedroom_b", "hall", "living", "study"], 1)


def test_rooms_of_one_place_that_stand_out_in_each_others_views_are_look_alikes():
    from localizer.likelihood_fit import CalibrationSamples

    samples = CalibrationSamples.from_queries(ONE_PLACE_BEDROOMS, ONE_PLACE_HOUSE)
    assert samples.lookalike_pairs == (("bedroom_a", "bedroom_b"),)
    assert samples.pair_tests == ("standout",)


def test_a_room_of_one_place_standing_out_from_one_side_only_is_no_look_alike():
    from localizer.likelihood_fit import CalibrationSamples

    # bedroom_b's view finds bedroom_a at chance level: perhaps a window, not a twin
    one_side = [
        (room, counts | {"bedroom_a": 0.7}) if room == "bedroom_b" else (room, counts)
        for room, counts in ONE_PLACE_BEDROOMS
    ]
    assert CalibrationSamples.from_queries(one_side, ONE_PLACE_HOUSE).lookalike_pairs == ()


def test_rooms_of_one_place_joined_by_a_door_never_stand_out_as_look_alikes():
    from localizer.likelihood_fit import CalibrationSamples

    door = [("bedroom_a", "bedroom_b")]
    samples = CalibrationSamples.from_queries(ONE_PLACE_BEDROOMS, ONE_PLACE_HOUSE, edges=door)
    assert samples.lookalike_pairs == ()


# a building recorded on one drive, one place per room (world seed 103): each office's view
# finds the other office above chance, and the corridor, seen through both doors, as high
ONE_PLACE_OFFICES = [
    ("office_a", {"office_b": 7.3, "corridor": 7.0, "kitchen": 2.4, "seminar": 1.4}),
    ("office_b", {"office_a": 13.8, "corridor": 5.5, "seminar": 2.7, "kitchen": 2.1}),
    ("corridor", {"office_a": 5.1, "office_b": 3.3, "seminar": 3.3, "kitchen": 2.6}),
]
ONE_PLACE_BUILDING = dict.fromkeys(["office_a", "office_b", "corridor", "kitchen", "seminar"], 1)
CORRIDOR_DOORS = [("corridor", room) for room in ("office_a", "office_b", "kitchen", "seminar")]


def test_rooms_of_one_place_stand_out_of_chance_not_of_the_room_seen_through_their_door():
    from localizer.likelihood_fit import CalibrationSamples

    samples = CalibrationSamples.from_queries(
        ONE_PLACE_OFFICES, ONE_PLACE_BUILDING, edges=CORRIDOR_DOORS
    )
    assert samples.lookalike_pairs == (("office_a", "office_b"),)
    assert samples.pair_tests == ("standout",)


def test_a_room_seen_through_no_door_as_high_as_the_twin_keeps_it_from_standing_out():
    from localizer.likelihood_fit import CalibrationSamples

    # the same views with the corridor joined to no room: as high as the twin, it is chance
    samples = CalibrationSamples.from_queries(ONE_PLACE_OFFICES, ONE_PLACE_BUILDING)
    assert samples.lookalike_pairs == ()


def test_one_view_of_a_room_stands_out_only_of_every_other_room_the_door_rooms_too():
    from localizer.likelihood_fit import CalibrationSamples

    # a building recorded two places per room (world seed 107): one of the storage room's
    # views finds the kitchen above every room but the two it opens onto; one view is half of
    # its room's views, and one side pairs only what stands out of them too
    views = [
        ("kitchen", {"kitchen": 98.7, "storage": 6.9, "corridor": 4.8, "office_b": 4.8}),
        ("kitchen", {"kitchen": 99.1, "office_b": 12.9, "office_a": 4.6, "storage": 1.5}),
        ("storage", {"storage": 4.2, "corridor": 2.3, "office_b": 2.3, "kitchen": 0.3}),
        ("storage", {"kitchen": 7.6, "corridor": 6.5, "seminar": 5.4, "storage": 4.2}),
    ]
    sizes = dict.fromkeys(["kitchen", "storage", "corridor", "seminar", "office_a", "office_b"], 2)
    doors = [("corridor", "kitchen"), ("corridor", "storage"), ("seminar", "storage")]
    assert CalibrationSamples.from_queries(views, sizes, edges=doors).lookalike_pairs == ()


def test_twins_read_on_a_counterpart_pair_at_chance_stay_aliased():
    # robot in office_a near its door: office_b's nearest place verified 14, the one
    # counterpart pair (3, 13) only 2 and 1: chance, which says nothing about which twin
    evidence = [Score(12, "office_b", 14), Score(0, "corridor", 7), Score(3, "office_a", 2)]
    evidence.append(Score(13, "office_b", 1))
    counts = room_inliers(evidence, ROOMS, count="inliers")
    read, aliased = twin_counts(
        evidence, ROOMS, counts, OFFICES, partners_of([(3, 13)]), count="inliers", min_count=6
    )
    assert aliased == OFFICES
    assert list(read) == list(counts)


def test_twins_read_on_counterparts_keep_the_group_as_likely_as_its_best_count():
    # the reading (40 against 30) says which office; office_b's nearer place (140) says how
    # strongly the frame shows an office against the corridor seen through the door (12)
    model = RatioLikelihood()
    counts = np.array([12.0, 40.0, 140.0, 0.0, 0.0, 0.0])
    read = np.array([12.0, 40.0, 30.0, 0.0, 0.0, 0.0])
    likelihood = model.from_counts(counts, compared=OFFICES, read=read)
    plain = model.from_counts(counts)
    assert likelihood[1] == pytest.approx(likelihood.max())
    assert likelihood[1] / likelihood[0] == pytest.approx(plain[2] / plain[0], rel=1e-9)
    assert likelihood[2] < likelihood[1]


@given(
    logs=st.lists(st.floats(-25, 25), min_size=4, max_size=4),
    read=st.lists(st.floats(-25, 25), min_size=4, max_size=4),
)
def test_a_compared_group_stands_at_its_best_and_its_rooms_at_most_the_cap_below(logs, read):
    out = lookalike_log_ratios(np.array(logs), compared=((0, 2, 3),), read=np.array(read))
    group = [out[0], out[2], out[3]]
    assert max(group) == max(logs[0], logs[2], logs[3])
    assert min(group) >= max(group) - MAX_TWIN_LOG_RATIO - 1e-9
    assert out[1] == logs[1]
    members = [0, 2, 3]
    assert out[members[int(np.argmax([read[m] for m in members]))]] == max(group)
