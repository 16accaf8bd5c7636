"""Likelihood model, Bayes filter over the room graph, and the localized/ambiguous/lost test."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from softmax_likelihood import SoftmaxLikelihood

from localizer.belief import (
    BeliefFilter,
    LocalizationState,
    PartlySeen,
    RoomBelief,
    StateThresholds,
    classify,
    entropy_bits,
    predict_on_graph,
    transition_matrix,
)
from localizer.likelihood import RatioLikelihood, room_inliers, room_likelihood

ROOMS = ("office_a", "office_b", "corridor", "lab", "kitchen")
EDGES = (("office_a", "corridor"), ("office_b", "corridor"), ("lab", "corridor"))


@dataclass(frozen=True)
class Ev:
    place_id: int
    room: str
    inliers: int
    coverage: float = 1.0  # the inliers surround the query

    @property
    def spread_inliers(self) -> float:
        return self.inliers * self.coverage


def evidence_for(inliers_by_room: dict[str, int]) -> list[Ev]:
    """One place per room with the given inliers, plus a weaker second place per room."""
    out = []
    for i, (room, n) in enumerate(inliers_by_room.items()):
        out += [Ev(2 * i, room, n), Ev(2 * i + 1, room, n // 3)]
    return out


# ---- likelihood ------------------------------------------------------------------------------


def test_a_zero_inlier_room_is_never_zeroed():
    """8000 against 0 inliers: the clipped log ratio keeps the other rooms above zero, so later
    frames can still outvote one mis-verified frame."""
    model = RatioLikelihood()
    lik = room_likelihood(evidence_for({"office_a": 8000, "office_b": 0}), ROOMS, model)
    odds = lik[ROOMS.index("office_b")] / lik[ROOMS.index("office_a")]
    assert odds == pytest.approx(math.exp(float(model.log_ratio(0.0)) - model.max_log_ratio))
    belief = BeliefFilter(ROOMS, EDGES)
    for _ in range(6):
        belief.update(lik)
    assert np.all(belief.probabilities > 0)


def test_nothing_matched_gives_a_flat_likelihood():
    model = RatioLikelihood(min_inliers=20)
    lik = room_likelihood(evidence_for({"office_a": 19, "lab": 5}), ROOMS, model)
    np.testing.assert_allclose(lik, np.full(len(ROOMS), 1 / len(ROOMS)))
    np.testing.assert_allclose(room_likelihood([], ROOMS, model), 1 / len(ROOMS))


def test_room_inliers_takes_the_best_place_and_rejects_unknown_rooms():
    counts = room_inliers(
        [Ev(1, "lab", 40), Ev(2, "lab", 90), Ev(3, "corridor", 7)], ROOMS, count="inliers"
    )
    assert counts[ROOMS.index("lab")] == 90
    assert counts[ROOMS.index("corridor")] == 7
    assert counts[ROOMS.index("office_a")] == 0
    with pytest.raises(ValueError, match="attic"):
        room_inliers([Ev(1, "attic", 40)], ROOMS, count="inliers")
    with pytest.raises(ValueError, match="-3 inliers"):
        room_inliers([Ev(1, "lab", -3)], ROOMS, count="inliers")


# ---- prediction ------------------------------------------------------------------------------


def naive_predict(belief, rooms, edges, stay):
    """The obvious double loop: each room keeps `stay`, gives the rest equally to neighbours."""
    neighbours = {room: set() for room in rooms}
    for a, b in edges:
        if a != b:
            neighbours[a].add(b)
            neighbours[b].add(a)
    prior = dict.fromkeys(rooms, 0.0)
    for room, p in zip(rooms, belief, strict=True):
        if not neighbours[room]:
            prior[room] += p
            continue
        prior[room] += p * stay
        for other in neighbours[room]:
            prior[other] += p * (1 - stay) / len(neighbours[room])
    return np.array([prior[r] for r in rooms])


def test_prediction_matches_the_naive_loop_on_random_graphs():
    rng = np.random.default_rng(7)
    for _ in range(300):
        n = int(rng.integers(1, 9))
        rooms = [f"r{i}" for i in range(n)]
        edges = [
            (rooms[i], rooms[j]) for i in range(n) for j in range(i + 1, n) if rng.random() < 0.35
        ]
        stay = float(rng.random())
        belief = rng.dirichlet(np.ones(n))
        fast = predict_on_graph(belief, transition_matrix(rooms, edges, stay))
        np.testing.assert_allclose(fast, naive_predict(belief, rooms, edges, stay), atol=1e-12)
        assert fast.sum() == pytest.approx(1.0)


def test_prediction_spreads_only_along_graph_edges():
    belief = BeliefFilter(ROOMS, EDGES, stay_probability=0.7)
    belief.reset({"office_a": 1.0})
    after_one = dict(zip(ROOMS, belief.predict(), strict=True))
    assert after_one["office_a"] == pytest.approx(0.7)
    assert after_one["corridor"] == pytest.approx(0.3)
    assert after_one["office_b"] == after_one["lab"] == after_one["kitchen"] == 0.0
    after_two = dict(zip(ROOMS, belief.predict(), strict=True))
    assert after_two["office_b"] > 0 and after_two["lab"] > 0  # two hops, through the corridor
    assert after_two["kitchen"] == 0.0  # no edge at all
    assert sum(after_two.values()) == pytest.approx(1.0)


def test_a_share_of_the_belief_may_go_anywhere_the_graph_notwithstanding():
    belief = BeliefFilter(ROOMS, EDGES, stay_probability=0.7)
    belief.reset({"kitchen": 1.0})  # a room without doors
    after = dict(zip(ROOMS, belief.predict(anywhere_probability=0.1), strict=True))
    share = 0.1 / len(ROOMS)
    assert after["kitchen"] == pytest.approx(0.9 + share)
    assert all(after[room] == pytest.approx(share) for room in ROOMS if room != "kitchen")


@given(
    st.integers(1, 8),
    st.floats(0.0, 1.0),
    st.floats(0.0, 1.0),
    st.integers(0, 2**32 - 1),
)
def test_a_prediction_with_a_share_anywhere_matches_the_naive_loop_mixed_with_the_uniform(
    n, stay, anywhere, seed
):
    rng = np.random.default_rng(seed)
    rooms = [f"r{i}" for i in range(n)]
    edges = [(rooms[i], rooms[j]) for i in range(n) for j in range(i + 1, n) if rng.random() < 0.4]
    belief = rng.dirichlet(np.ones(n))
    fast = predict_on_graph(belief, transition_matrix(rooms, edges, stay, anywhere))
    naive = (1 - anywhere) * naive_predict(belief, rooms, edges, stay) + anywhere / n
    np.testing.assert_allclose(fast, naive, atol=1e-12)
    assert fast.sum() == pytest.approx(1.0)


def test_stay_probability_override_is_for_one_move_only():
    belief = BeliefFilter(ROOMS, EDGES, stay_probability=0.5)
    belief.reset({"lab": 1.0})
    assert belief.predict(stay_probability=1.0)[ROOMS.index("lab")] == pytest.approx(1.0)
    assert belief.predict()[ROOMS.index("lab")] == pytest.approx(0.5)


def test_transition_rejects_unknown_rooms_and_bad_stay():
    with pytest.raises(ValueError, match="attic"):
        transition_matrix(ROOMS, [("lab", "attic")], 0.8)
    with pytest.raises(ValueError, match="stay_probability"):
        transition_matrix(ROOMS, EDGES, 1.2)
    with pytest.raises(ValueError, match="anywhere_probability"):
        transition_matrix(ROOMS, EDGES, 0.8, -0.1)
    with pytest.raises(ValueError, match="unique"):
        BeliefFilter(["lab", "lab"])


# ---- update and state ------------------------------------------------------------------------


@settings(max_examples=200, deadline=None)
@given(
    prior=st.lists(st.floats(0.0, 10.0), min_size=5, max_size=5).filter(lambda w: sum(w) > 1e-6),
    counts=st.lists(st.integers(0, 1000), min_size=5, max_size=5),
    moves=st.lists(st.booleans(), max_size=4),
)
def test_belief_stays_a_distribution(prior, counts, moves):
    belief = BeliefFilter(ROOMS, EDGES)
    belief.reset(dict(zip(ROOMS, prior, strict=True)))
    lik = RatioLikelihood().from_room_inliers(np.array(counts, dtype=float))
    for moved in moves:
        if moved:
            belief.predict()
        belief.update(lik)
    p = belief.probabilities
    assert np.all(p >= 0)
    assert p.sum() == pytest.approx(1.0)


def test_consistent_updates_converge_to_localized():
    # the softmax model: a 10-inlier lead counts the same at any level
    belief = BeliefFilter(ROOMS, EDGES)
    evidence = evidence_for({"office_a": 310, "office_b": 300, "corridor": 15, "lab": 12})
    lik = room_likelihood(evidence, ROOMS, SoftmaxLikelihood())
    states = []
    for _ in range(6):
        belief.update(lik)
        states.append(classify(belief.probabilities, evidence_max_inliers=310))
    assert states[0] is LocalizationState.AMBIGUOUS
    assert states[-1] is LocalizationState.LOCALIZED
    assert ROOMS[int(np.argmax(belief.probabilities))] == "office_a"


def test_two_equal_rooms_are_ambiguous():
    belief = BeliefFilter(ROOMS, EDGES)
    evidence = evidence_for({"office_a": 300, "office_b": 300, "corridor": 10})
    for _ in range(10):
        belief.update(room_likelihood(evidence, ROOMS))
    p = belief.probabilities
    assert p[0] == pytest.approx(p[1])
    assert classify(p, evidence_max_inliers=300) is LocalizationState.AMBIGUOUS
    snapshot = RoomBelief.from_probabilities(ROOMS, p, evidence=evidence, count="spread")
    assert snapshot.state is LocalizationState.AMBIGUOUS
    assert {snapshot.top[0], snapshot.second[0]} == {"office_a", "office_b"}


def test_all_zero_evidence_is_lost_and_leaves_the_belief_alone():
    belief = BeliefFilter(ROOMS, EDGES)
    belief.reset({"lab": 0.9, "corridor": 0.1})
    before = belief.probabilities
    evidence = [Ev(i, room, 0) for i, room in enumerate(ROOMS)]
    after = belief.update(room_likelihood(evidence, ROOMS))
    np.testing.assert_allclose(after, before)
    assert classify(after, evidence_max_inliers=0) is LocalizationState.LOST
    assert (
        RoomBelief.from_probabilities(ROOMS, after, evidence=evidence, count="spread").state
        == "lost"
    )


def test_classify_thresholds_are_configuration():
    p = np.array([0.8, 0.2])  # ratio 4, 0.72 bits
    assert classify(p) is LocalizationState.AMBIGUOUS
    assert classify(p, StateThresholds(localized_ratio=4.0)) is LocalizationState.LOCALIZED
    strict = StateThresholds(localized_ratio=4.0, max_entropy_bits=0.5)
    assert classify(p, strict) is LocalizationState.AMBIGUOUS
    assert classify(np.array([1.0])) is LocalizationState.LOCALIZED
    with pytest.raises(ValueError, match="localized_ratio"):
        StateThresholds(localized_ratio=0.5)


def test_reset_with_a_prior_and_uniform():
    belief = BeliefFilter(ROOMS, EDGES)
    belief.reset({"lab": 3.0, "corridor": 1.0})
    assert belief.as_dict()["lab"] == pytest.approx(0.75)
    assert belief.as_dict()["office_a"] == 0.0
    belief.reset()
    np.testing.assert_allclose(belief.probabilities, 1 / len(ROOMS))


@pytest.mark.parametrize(
    "prior, match",
    [
        ({"attic": 1.0}, "unknown room 'attic'"),
        ({"lab": -0.1, "corridor": 1.0}, "'lab' must be >= 0"),
        ({"lab": math.nan}, "'lab' must be >= 0"),
        ({"lab": 0.0, "corridor": 0.0}, "all zero"),
        ({}, "all zero"),
    ],
)
def test_reset_rejects_bad_priors(prior, match):
    belief = BeliefFilter(ROOMS, EDGES)
    with pytest.raises(ValueError, match=match):
        belief.reset(prior)
    np.testing.assert_allclose(belief.probabilities, 1 / len(ROOMS))  # unchanged


def test_update_rejects_bad_likelihoods():
    belief = BeliefFilter(ROOMS, EDGES)
    with pytest.raises(ValueError, match="shape"):
        belief.update(np.ones(3))
    with pytest.raises(ValueError, match=">= 0"):
        belief.update(np.array([1, 1, 1, 1, -1.0]))
    belief.reset({"lab": 1.0})
    with pytest.raises(ValueError, match="zero wherever"):
        belief.update(np.array([1.0, 1.0, 1.0, 0.0, 1.0]))


def test_entropy_bits():
    assert entropy_bits(np.array([0.5, 0.5])) == pytest.approx(1.0)
    assert entropy_bits(np.full(4, 0.25)) == pytest.approx(2.0)
    assert entropy_bits(np.array([1.0, 0.0])) == pytest.approx(0.0)


def test_room_belief_json_round_trip():
    evidence = evidence_for({"office_a": 120, "lab": 40})
    p = np.array([0.6, 0.3, 0.05, 0.05, 0.0])
    snapshot = RoomBelief.from_probabilities(
        ROOMS, p, evidence=evidence, stamp_s=12.5, count="spread"
    )
    data = snapshot.to_json()
    assert data["rooms"] == pytest.approx(dict(zip(ROOMS, p, strict=True)))
    assert data["state"] == "ambiguous"
    assert data["top"] == {"room": "office_a", "probability": 0.6}
    assert data["second"]["room"] == "office_b"
    assert data["top_two_ratio"] == pytest.approx(2.0)
    assert data["best_place"] == {"place_id": 0, "room": "office_a", "inliers": 120}
    assert data["entropy_bits"] == pytest.approx(entropy_bits(p))
    assert RoomBelief.from_json(data) == snapshot
    homing = RoomBelief.from_json({**data, "state": "homing"})
    assert homing.state is LocalizationState.HOMING
    with pytest.raises(ValueError, match="schema"):
        RoomBelief.from_json({**data, "schema": 99})
    with pytest.raises(ValueError, match="a belief needs the field 'state'"):
        RoomBelief.from_json({k: v for k, v in data.items() if k != "state"})


def test_a_belief_that_waits_for_a_room_seen_in_part_says_so_in_its_message():
    plain = RoomBelief.from_probabilities(("a", "b"), np.array([0.95, 0.05]))
    assert "partly_seen" not in plain.to_json()  # readers that do not know it see nothing new
    waiting = replace(plain, partly_seen=PartlySeen("a", 0.44, 0.6))
    data = waiting.to_json()
    assert data["partly_seen"] == {"room": "a", "horizon_share": 0.44, "needed_share": 0.6}
    assert RoomBelief.from_json(data) == waiting


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            {"partly_seen": {"room": "a", "horizon_share": 1.5, "needed_share": 0.6}},
            r"partly_seen.horizon_share must be in \[0, 1\]",
        ),
        ({"partly_seen": {"horizon_share": 0.4, "needed_share": 0.6}}, "partly_seen.room"),
        ({"partly_seen": 0.4}, "partly_seen must be an object"),
        ({"rooms": {}}, "rooms must be a non-empty object"),
        ({"rooms": {"a": 1.5}}, r"rooms\['a'\] must be a probability"),
        ({"state": "confused"}, "state must be one of"),
        ({"entropy_bits": "high"}, "entropy_bits must be a finite number"),
        ({"best_place": {"place_id": "4", "inliers": 1}}, "best_place.place_id must be an integer"),
    ],
)
def test_a_bad_belief_message_names_the_field(change, message):
    data = RoomBelief.from_probabilities(("a", "b"), np.array([0.5, 0.5])).to_json()
    with pytest.raises(ValueError, match=message):
        RoomBelief.from_json({**data, **change})


def test_the_lost_test_reads_the_count_the_likelihood_reads():
    # 30 inliers, all in a quarter of the horizon: 7.5 spread inliers
    evidence = [Ev(1, "lab", 30, coverage=0.25)]
    thresholds = StateThresholds(lost_min_inliers=10)
    p = np.full(len(ROOMS), 1.0 / len(ROOMS))
    raw = RoomBelief.from_probabilities(ROOMS, p, thresholds, evidence, count="inliers")
    spread = RoomBelief.from_probabilities(ROOMS, p, thresholds, evidence, count="spread")
    assert raw.state is not LocalizationState.LOST
    assert spread.state is LocalizationState.LOST


def test_a_belief_with_evidence_needs_the_count():
    with pytest.raises(ValueError, match="count"):
        RoomBelief.from_probabilities(ROOMS, np.full(5, 0.2), evidence=[Ev(1, "lab", 30)])
