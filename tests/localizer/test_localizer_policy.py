"""Disambiguation policies: the thesis's "most likely" and the "separating" one, and a comparison
on a synthetic look-alike world (run this file as a script to print the comparison)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from softmax_likelihood import SoftmaxLikelihood

from localizer.active import active_step
from localizer.belief import BeliefFilter, RoomBelief
from localizer.likelihood import room_likelihood
from localizer.policy import (
    POLICIES,
    DiscriminativePolicy,
    PlaceSimilarity,
    PolicyContext,
    ThesisPolicy,
    make_policy,
    separating_pairs,
)
from mapdb.records import Place


@dataclass(frozen=True)
class Ev:
    place_id: int
    room: str
    inliers: int
    coverage: float = 1.0  # the inliers surround the query

    @property
    def spread_inliers(self) -> float:
        return self.inliers * self.coverage


# ---- the thesis policy -----------------------------------------------------------------------

PLACES = [
    Place(1, "a", 0.0, 0.0),
    Place(2, "a", 1.0, 0.0),
    Place(3, "a", 2.0, 0.0),
    Place(11, "b", 0.0, 0.0),
    Place(12, "b", 1.0, 0.0),
    Place(21, "c", 0.0, 0.0),
]
EVIDENCE = [Ev(1, "a", 40), Ev(2, "a", 250), Ev(3, "a", 90), Ev(11, "b", 260), Ev(12, "b", 30)]


def rb(probabilities: dict[str, float]) -> RoomBelief:
    """A belief snapshot with these room probabilities."""
    return RoomBelief.from_probabilities(
        tuple(probabilities), np.array(list(probabilities.values()))
    )


def ctx(tried=(), similarity: PlaceSimilarity | None = None, **options) -> PolicyContext:
    """A policy context: places tried, and a similarity function serving ``similarity``."""
    serve = None if similarity is None else (lambda rows, columns: similarity)
    return PolicyContext(tried=frozenset(tried), similarity=serve, **options)


def test_thesis_picks_the_best_place_of_the_most_likely_room():
    policy = ThesisPolicy()
    belief = {"a": 0.6, "b": 0.35, "c": 0.05}
    # b's place 11 has the most inliers overall, but a is the most likely room
    assert policy.choose(rb(belief), EVIDENCE, PLACES, ctx()) == 2
    assert policy.choose(rb(belief), EVIDENCE, PLACES, ctx({2})) == 3
    assert policy.choose(rb(belief), EVIDENCE, PLACES, ctx({2, 3})) == 1


def test_thesis_moves_to_the_next_room_then_gives_up():
    policy = ThesisPolicy()
    belief = {"a": 0.6, "b": 0.35, "c": 0.05}
    assert policy.choose(rb(belief), EVIDENCE, PLACES, ctx({1, 2, 3})) == 11
    assert policy.choose(rb(belief), EVIDENCE, PLACES, ctx({1, 2, 3, 11})) == 12
    assert (
        policy.choose(rb(belief), EVIDENCE, PLACES, ctx({1, 2, 3, 11, 12})) == 21
    )  # no evidence there
    assert policy.choose(rb(belief), EVIDENCE, PLACES, ctx({1, 2, 3, 11, 12, 21})) is None
    assert (
        ThesisPolicy(min_room_probability=0.1).choose(
            rb(belief), EVIDENCE, PLACES, ctx({1, 2, 3, 11, 12})
        )
        is None
    )


def test_thesis_accepts_a_room_belief_snapshot():
    snapshot = RoomBelief.from_probabilities(("a", "b", "c"), np.array([0.2, 0.7, 0.1]))
    assert ThesisPolicy().choose(snapshot, EVIDENCE, PLACES, ctx()) == 11


# ---- the separating policy -------------------------------------------------------------------


def lookalike_similarity(door_place: int = 3, door_loss: float = 0.4) -> PlaceSimilarity:
    """Rooms a and b identical except at one place of a (``door_place``), whose view through the
    door the b places explain only partly. Self-match 400, same-room 200, look-alike twin 380."""
    ids = [p.id for p in PLACES]
    room = {p.id: p.room for p in PLACES}
    twin = {1: 11, 2: 12, 3: 12, 11: 1, 12: 2}
    matrix = np.full((len(ids), len(ids)), 10.0)
    for i, pi in enumerate(ids):
        for j, pj in enumerate(ids):
            if pi == pj:
                matrix[i, j] = 400
            elif room[pi] == room[pj]:
                matrix[i, j] = 200
            elif twin.get(pi) == pj:
                matrix[i, j] = 380
            elif room[pi] in "ab" and room[pj] in "ab":
                matrix[i, j] = 180
    row = ids.index(door_place)
    for j, pj in enumerate(ids):
        if room[pj] == "b":
            matrix[row, j] *= 1 - door_loss
    return PlaceSimilarity(tuple(ids), matrix)


def test_separating_picks_the_place_that_differs():
    belief = {"a": 0.5, "b": 0.45, "c": 0.05}
    for door_place in (1, 2, 3):
        policy = DiscriminativePolicy(travel_cost_per_m=0.0)
        context = ctx(similarity=lookalike_similarity(door_place))
        assert policy.choose(rb(belief), EVIDENCE, PLACES, context) == door_place
    # the thesis goes to the best-matching place instead, however the rooms differ
    assert ThesisPolicy().choose(rb(belief), EVIDENCE, PLACES, ctx()) == 2


def test_separating_pairs_are_all_the_policy_reads():
    belief = {"a": 0.5, "b": 0.45, "c": 0.01}
    candidates, rivals = separating_pairs(belief, PLACES, tried={2})
    assert candidates == (1, 3)
    assert rivals == (11, 12)  # c is below the 2 % rival threshold
    full = lookalike_similarity(3)
    keep = [full.index(p) for p in (*candidates, *rivals)]
    only_pairs = PlaceSimilarity((*candidates, *rivals), full.inliers[np.ix_(keep, keep)])
    asked = []

    def similarity(rows, columns):
        asked.append((rows, columns))
        return only_pairs

    context = PolicyContext(tried=frozenset({2}), similarity=similarity)
    choice = DiscriminativePolicy().choose(rb(belief), EVIDENCE, PLACES, context)
    assert asked == [(candidates, rivals)]  # the policy asks for exactly these entries
    full_choice = DiscriminativePolicy().choose(rb(belief), EVIDENCE, PLACES, ctx({2}, full))
    assert choice == full_choice == 3


def test_separating_pairs_are_empty_when_everything_was_tried():
    assert separating_pairs({"a": 1.0}, PLACES, tried={1, 2, 3, 11, 12, 21}) == ((), ())


def test_separating_score_is_documented_formula():
    similarity = lookalike_similarity(3, door_loss=0.4)
    policy = DiscriminativePolicy(travel_cost_per_m=0.0, min_rival_probability=0.02)
    belief = {"a": 0.5, "b": 0.45, "c": 0.05}
    # place 3: best b place explains 380*0.6/400; c explains 10/400; rivals weighted .45/.5, .05/.5
    expected = 1 - (0.9 * (380 * 0.6 / 400) + 0.1 * (10 / 400))
    assert policy.separation(similarity, 3, "a", belief, PLACES) == pytest.approx(expected)
    assert policy.separation(similarity, 2, "a", {"a": 1.0}, PLACES) == 1.0  # no rivals


def test_separating_trades_separation_against_travel():
    belief = {"a": 0.5, "b": 0.5, "c": 0.0}
    similarity = lookalike_similarity(3, door_loss=0.05)  # door place only slightly better
    here = ctx(similarity=similarity, position_xy_m_by_room={"a": (0.0, 0.0)})
    assert (
        DiscriminativePolicy(travel_cost_per_m=0.0).choose(rb(belief), EVIDENCE, PLACES, here) == 3
    )
    # 2 m to place 3 cost 0.2 > its ~0.05 separation gain: stay near (place 1 is where we are)
    assert (
        DiscriminativePolicy(travel_cost_per_m=0.1).choose(rb(belief), EVIDENCE, PLACES, here) == 1
    )


def test_separating_skips_tried_places_and_rooms():
    policy, similarity = DiscriminativePolicy(), lookalike_similarity(3)
    belief = rb({"a": 0.5, "b": 0.45, "c": 0.05})
    assert policy.choose(belief, EVIDENCE, PLACES, ctx({3}, similarity)) in {1, 2}
    assert policy.choose(belief, EVIDENCE, PLACES, ctx({1, 2, 3}, similarity)) in {11, 12}
    everything = {p.id for p in PLACES}
    assert policy.choose(belief, EVIDENCE, PLACES, ctx(everything, similarity)) is None


def test_similarity_validation_and_missing_places():
    with pytest.raises(ValueError, match="shape"):
        PlaceSimilarity((1, 2), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="unique"):
        PlaceSimilarity((1, 1), np.zeros((2, 2)))
    with pytest.raises(ValueError, match=">= 0"):
        PlaceSimilarity((1, 2), -np.ones((2, 2)))
    partial = PlaceSimilarity((1, 2), np.eye(2))
    with pytest.raises(ValueError, match="place 3 is not in the similarity matrix"):
        DiscriminativePolicy().choose(rb({"a": 1.0}), EVIDENCE, PLACES, ctx({1, 2}, partial))


def test_separating_without_a_similarity_says_what_it_needs():
    with pytest.raises(ValueError, match="separating policy needs a view similarity"):
        DiscriminativePolicy().choose(rb({"a": 0.5, "b": 0.5}), EVIDENCE, PLACES, ctx())


def test_registry_and_make_policy():
    assert set(POLICIES) == {"most-likely", "separating"}
    assert isinstance(make_policy("most-likely"), ThesisPolicy)
    assert make_policy("separating", travel_cost_per_m=0.1).travel_cost_per_m == 0.1
    with pytest.raises(ValueError, match=r"unknown disambiguation policy 'greedy'.*most-likely"):
        make_policy("greedy")
    with pytest.raises(ValueError, match="cannot build policy 'separating'"):
        make_policy("separating", similarity=lookalike_similarity())


# ---- comparison on a synthetic look-alike world ----------------------------------------------
# Two offices identical in their own frames, 5 places on a line x = 0..4 m, the door at x = 4;
# the share of a view that only the true office has (the corridor through the door) grows
# towards the door. Plus a corridor and a lab. A capture at index k of the true office scores
# every stored place by the same similarity model plus Gaussian noise (sigma 8 inliers).

N_IN_OFFICE = 5
DOOR_SHARE = (0.0, 0.01, 0.03, 0.08, 0.15)
WORLD_ROOMS = ("office_a", "office_b", "corridor", "lab")
WORLD_EDGES = (("office_a", "corridor"), ("office_b", "corridor"), ("lab", "corridor"))


def world_places() -> list[Place]:
    places = []
    for r, room in enumerate(WORLD_ROOMS):
        count = N_IN_OFFICE if room.startswith("office") else 3
        places += [Place(10 * r + k, room, float(k), 0.0) for k in range(count)]
    return places


def view_similarity(room_here: str, k: int, place: Place) -> float:
    """Expected inliers of a capture at index k of room_here against a stored place."""
    same_layout = room_here.startswith("office") and place.room.startswith("office")
    if place.room != room_here and not same_layout:
        return 10.0
    base = 300.0 * math.exp(-abs(k - place.x_m) / 1.5)
    return base if place.room == room_here else base * (1 - DOOR_SHARE[k])


def world_similarity(places: list[Place]) -> PlaceSimilarity:
    matrix = np.array([[view_similarity(c.room, int(c.x_m), q) for q in places] for c in places])
    np.fill_diagonal(matrix, 400.0)  # self-match
    return PlaceSimilarity(tuple(p.id for p in places), matrix)


def run_episode(policy, true_room: str, start_k: int, rng, max_moves: int = 12):
    """Moves, travel (m) and the final belief's top room, driving by :func:`active_step` (the
    active loop's decision) with a belief updated after each capture."""
    places = world_places()
    by_id = {p.id: p for p in places}
    belief = BeliefFilter(WORLD_ROOMS, WORLD_EDGES, stay_probability=0.8)
    similarity = world_similarity(places)
    context = PolicyContext(similarity=lambda rows, columns: similarity)
    k, moves, travel_m = start_k, 0, 0.0

    def capture():
        noisy = [
            Ev(p.id, p.room, max(0, round(view_similarity(true_room, k, p) + rng.normal(0, 8))))
            for p in places
        ]
        # synthetic counts, no map to calibrate on: the uncalibrated model
        belief.update(room_likelihood(noisy, WORLD_ROOMS, SoftmaxLikelihood()))
        return noisy

    evidence = capture()
    while True:
        snapshot = RoomBelief.from_probabilities(
            WORLD_ROOMS, belief.probabilities, None, evidence, count="inliers"
        )
        target = active_step(snapshot, evidence, places, policy, context, max_moves, moves)
        if target is None:
            break
        context = context.trying(target)
        moves += 1
        if by_id[target].room.startswith("office"):  # homing ends at the same spot of the true room
            new_k = int(by_id[target].x_m)
            travel_m += abs(new_k - k)
            k = new_k
        belief.predict(stay_probability=0.99)  # short move inside the room
        evidence = capture()
    top = WORLD_ROOMS[int(np.argmax(belief.probabilities))]
    return moves, travel_m, top


def compare(n_episodes: int, seed: int = 0) -> dict[str, dict[str, float]]:
    policies = {
        "most-likely": ThesisPolicy(),
        "separating": DiscriminativePolicy(),
    }
    results = {}
    for name, policy in policies.items():
        rng = np.random.default_rng(seed)
        runs = [
            run_episode(policy, ("office_a", "office_b")[i % 2], int(rng.integers(0, 3)), rng)
            for i in range(n_episodes)
        ]
        truth = [("office_a", "office_b")[i % 2] for i in range(n_episodes)]
        results[name] = {
            "mean_moves": float(np.mean([r[0] for r in runs])),
            "mean_travel_m": float(np.mean([r[1] for r in runs])),
            "correct": float(np.mean([r[2] == t for r, t in zip(runs, truth, strict=True)])),
        }
    return results


def test_separating_needs_fewer_moves_than_the_thesis_on_lookalike_offices():
    results = compare(n_episodes=40)
    thesis, separating = results["most-likely"], results["separating"]
    assert separating["correct"] >= thesis["correct"]
    assert separating["mean_moves"] < thesis["mean_moves"]
    assert separating["correct"] >= 0.9


if __name__ == "__main__":
    for policy_name, figures in compare(n_episodes=400).items():
        print(policy_name, {k: round(v, 3) for k, v in figures.items()})


def recorded_twins_similarity() -> PlaceSimilarity:
    """Rooms a and b look alike but were recorded at different spots: a's places share only
    a fifth of their view with any b place (180 of 400 at most), so each looks separating."""
    ids = [p.id for p in PLACES]
    room = {p.id: p.room for p in PLACES}
    matrix = np.full((len(ids), len(ids)), 10.0)
    for i, pi in enumerate(ids):
        for j, pj in enumerate(ids):
            if pi == pj:
                matrix[i, j] = 400
            elif room[pi] == room[pj]:
                matrix[i, j] = 200
            elif room[pi] in "ab" and room[pj] in "ab":
                matrix[i, j] = 80
    return PlaceSimilarity(tuple(ids), matrix)


TWINS = {"a": frozenset({"b"}), "b": frozenset({"a"})}


def test_against_a_look_alike_only_a_counterpart_separates():
    policy = DiscriminativePolicy(travel_cost_per_m=0.0)
    belief = {"a": 0.5, "b": 0.5, "c": 0.0}
    similarity = recorded_twins_similarity()
    context = ctx(lookalikes=TWINS, counterparts={2: frozenset({12}), 12: frozenset({2})})
    assert policy.separation(similarity, 1, "a", belief, PLACES, context) == 0.0
    assert policy.separation(similarity, 2, "a", belief, PLACES, context) == pytest.approx(0.8)
    without = policy.separation(similarity, 1, "a", belief, PLACES)  # the counts alone
    assert without == pytest.approx(0.8)


def test_the_separating_policy_drives_to_a_counterpart_of_a_look_alike():
    belief = rb({"a": 0.5, "b": 0.5, "c": 0.0})
    context = ctx(
        similarity=recorded_twins_similarity(),
        lookalikes=TWINS,
        counterparts={2: frozenset({12}), 12: frozenset({2})},
    )
    assert DiscriminativePolicy().choose(belief, EVIDENCE, PLACES, context) == 2


def test_twins_without_counterparts_give_the_separating_policy_nowhere_to_drive():
    belief = rb({"a": 0.5, "b": 0.5, "c": 0.0})
    context = ctx(similarity=recorded_twins_similarity(), lookalikes=TWINS)
    assert DiscriminativePolicy().choose(belief, EVIDENCE, PLACES, context) is None


def test_a_look_alike_rivals_counterpart_place_is_a_candidate_too():
    # a's counterpart place was tried; b's counterpart of it is the one left that tells them apart
    belief = rb({"a": 0.5, "b": 0.5, "c": 0.0})
    context = ctx(
        {2},
        similarity=recorded_twins_similarity(),
        lookalikes=TWINS,
        counterparts={2: frozenset({12}), 12: frozenset({2})},
    )
    assert DiscriminativePolicy().choose(belief, EVIDENCE, PLACES, context) == 12
