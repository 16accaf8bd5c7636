"""Home directions from the bearings of two views (the thesis's ALV, the matched ALV, the
wedge vote) and the matched compass, measured against the true direction (eq. 5.5)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from homing.alv import alv_from_bearings
from homing.compass import matched_rotation_rad
from homing.home_directions import (
    alv_home_directions_rad,
    matched_alv_direction_rad,
    wedge_vote_direction_rad,
)
from homing.thesis.evaluation import pair_errors_deg, true_home_direction_rad


def _bearings(landmarks: np.ndarray, position: np.ndarray, heading_rad: float) -> np.ndarray:
    d = landmarks - position
    return np.arctan2(d[:, 1], d[:, 0]) - heading_rad


def _in_wedges(direction_rad: float, u: np.ndarray, w: np.ndarray, slack_rad: float) -> np.ndarray:
    """For each row, whether ``direction_rad`` lies within ``slack_rad`` of the shorter arc from
    unit vector ``u`` to unit vector ``w`` (a positive combination ``a u + b w``)."""
    d = np.array([np.cos(direction_rad), np.sin(direction_rad)])
    arc = np.arccos(np.clip(np.einsum("ij,ij->i", u, w), -1.0, 1.0))
    to_u = np.arccos(np.clip(u @ d, -1.0, 1.0))
    to_w = np.arccos(np.clip(w @ d, -1.0, 1.0))
    return to_u + to_w <= arc + 2 * slack_rad


landmark_sets = st.integers(0, 10_000).map(
    lambda seed: np.random.default_rng(seed).uniform([-5, -5], [5, 5], size=(40, 2))
)
positions = st.tuples(st.floats(-1.5, 1.5), st.floats(-1.5, 1.5)).map(np.array)
headings = st.floats(-math.pi, math.pi)


@settings(max_examples=60, deadline=None)
@given(landmarks=landmark_sets, here=positions, home=positions, h1=headings, h2=headings)
def test_home_directions_point_home_within_90_deg(landmarks, here, home, h1, h2) -> None:
    """With fixed landmarks around both places, every method's home vector is within 90° of
    the true direction (the ALV's convergence; Lambrinos et al. 2000), whatever the headings."""
    if np.linalg.norm(home - here) < 0.2:
        return
    b_here, b_home = _bearings(landmarks, here, h1), _bearings(landmarks, home, h2)
    truth = true_home_direction_rad(here, home)
    rotation = h2 - h1
    thesis = alv_home_directions_rad(
        alv_from_bearings(b_here)[None], alv_from_bearings(b_home)[None], np.array([rotation])
    )
    matches = np.column_stack([np.arange(40), np.arange(40)])
    matched = matched_alv_direction_rad(b_here, b_home, matches, rotation)
    voted = wedge_vote_direction_rad(b_here, b_home, matches, rotation)
    for direction in (float(thesis[0]), matched, voted):
        assert float(pair_errors_deg(direction, h1, truth)) < 90.0
    # With exact correspondences every wedge holds the true direction, so the arc common to all
    # wedges is not empty and the vote (its centre) lies in every wedge: it is bounded by the
    # same landmarks as the truth. (How close it comes depends on how wide that arc is.)
    u = np.column_stack([np.cos(b_here), np.sin(b_here)])
    minus_v = -np.column_stack([np.cos(b_home + rotation), np.sin(b_home + rotation)])
    # A landmark (almost) on the line through both places makes a wedge of 180°, which has no
    # shorter side: such wedges say nothing and are left out.
    arc = np.arccos(np.clip(np.einsum("ij,ij->i", u, minus_v), -1.0, 1.0))
    defined = arc < np.pi - np.deg2rad(2.0)
    assert np.all(_in_wedges(truth - h1, u[defined], minus_v[defined], slack_rad=1e-9))
    assert np.all(_in_wedges(voted, u[defined], minus_v[defined], slack_rad=1e-9))


@settings(max_examples=40, deadline=None)
@given(landmarks=landmark_sets, here=positions, h1=headings, h2=headings)
def test_matched_rotation_is_exact_without_parallax(landmarks, here, h1, h2) -> None:
    b_here, b_home = _bearings(landmarks, here, h1), _bearings(landmarks, here, h2)
    matches = np.column_stack([np.arange(40), np.arange(40)])
    rotation = matched_rotation_rad(b_here, b_home, matches)
    assert math.remainder(rotation - (h2 - h1), 2 * math.pi) == pytest.approx(0.0, abs=1e-9)


def test_vote_rejects_a_minority_of_mismatches() -> None:
    rng = np.random.default_rng(0)
    landmarks = rng.uniform(-5, 5, size=(60, 2))
    here, home = np.array([-1.0, 0.0]), np.array([1.0, 0.5])
    b_here, b_home = _bearings(landmarks, here, 0.0), _bearings(landmarks, home, 0.0)
    matches = np.column_stack([np.arange(60), np.arange(60)])
    matches[:15, 1] = rng.permutation(matches[:15, 1])  # a quarter mismatched
    truth = true_home_direction_rad(here, home)
    voted = wedge_vote_direction_rad(b_here, b_home, matches, 0.0)
    assert float(pair_errors_deg(voted, 0.0, truth)) < 5.0


def test_no_matches_or_zero_vector_give_nan() -> None:
    none = np.zeros((0, 2), dtype=np.int64)
    b = np.array([0.1, 1.0, 2.0])
    assert math.isnan(matched_rotation_rad(b, b, none))
    assert math.isnan(matched_alv_direction_rad(b, b, none, 0.0))
    assert math.isnan(wedge_vote_direction_rad(b, b, none, 0.0))
    same = alv_from_bearings(b)[None]
    assert np.isnan(alv_home_directions_rad(same, same, np.array([0.0])))[0]


def test_vote_leaves_out_nan_bearings_and_empty_wedges() -> None:
    rng = np.random.default_rng(1)
    landmarks = rng.uniform(-5, 5, size=(30, 2))
    here, home = np.array([-1.0, 0.0]), np.array([1.0, 0.5])
    b_here, b_home = _bearings(landmarks, here, 0.0), _bearings(landmarks, home, 0.0)
    matches = np.column_stack([np.arange(30), np.arange(30)])
    clean = wedge_vote_direction_rad(b_here, b_home, matches, 0.0)
    b_here[3] = np.nan
    assert wedge_vote_direction_rad(b_here, b_home, matches, 0.0) == pytest.approx(clean, abs=0.05)
    assert math.isnan(wedge_vote_direction_rad(b_here[3:4], b_home[3:4], matches[:1] * 0, 0.0))
    # a landmark straight behind here and ahead of home: its wedge is a single direction
    assert math.isnan(
        wedge_vote_direction_rad(np.array([0.5]), np.array([0.5 + np.pi]), matches[:1] * 0, 0.0)
    )
