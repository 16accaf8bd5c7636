"""``azimuth_coverage``: how much of the query's horizon a place's inliers cover, and the
``spread`` count the likelihood reads (a room seen through a door fills a narrow arc)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from localizer.evidence import COVERAGE_ARC_DEG, PlaceEvidence, azimuth_coverage
from localizer.likelihood import RatioLikelihood, room_inliers, room_likelihood


def rays_at(azimuth_deg: list[float] | np.ndarray, elevation_deg: float = 0.0) -> np.ndarray:
    """Unit rays (robot frame) at the given azimuths, counter-clockwise from the heading."""
    a = np.radians(np.asarray(azimuth_deg, dtype=float))
    e = math.radians(elevation_deg)
    return np.column_stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.full_like(a, e)])


def test_one_inlier_covers_one_arc() -> None:
    assert azimuth_coverage(rays_at([40.0])) == pytest.approx(COVERAGE_ARC_DEG / 360.0)


def test_no_inliers_cover_nothing() -> None:
    assert azimuth_coverage(np.zeros((0, 3))) == 0.0


def test_inliers_all_round_cover_the_whole_horizon() -> None:
    assert azimuth_coverage(rays_at(np.arange(0.0, 360.0, 20.0))) == pytest.approx(1.0)


def test_a_doorway_full_of_inliers_covers_its_arc_only() -> None:
    door = rays_at(np.linspace(80.0, 140.0, 60))  # 60 inliers through a 60-degree opening
    assert azimuth_coverage(door) == pytest.approx((60.0 + COVERAGE_ARC_DEG) / 360.0)


def test_elevation_does_not_matter() -> None:
    azimuths = [10.0, 100.0, 250.0]
    assert azimuth_coverage(rays_at(azimuths, 30.0)) == pytest.approx(
        azimuth_coverage(rays_at(azimuths))
    )


def test_bad_arc_is_refused() -> None:
    with pytest.raises(ValueError, match="arc_deg"):
        azimuth_coverage(rays_at([0.0]), arc_deg=0.0)


@given(
    st.lists(st.floats(0.0, 360.0, allow_nan=False), min_size=1, max_size=40),
    st.floats(-720.0, 720.0, allow_nan=False),
)
def test_a_yaw_roll_keeps_the_coverage(azimuths_deg: list[float], roll_deg: float) -> None:
    rolled = np.asarray(azimuths_deg) + roll_deg
    assert azimuth_coverage(rays_at(rolled)) == pytest.approx(
        azimuth_coverage(rays_at(azimuths_deg)), abs=1e-9
    )


@given(st.lists(st.floats(0.0, 360.0, allow_nan=False), min_size=1, max_size=40))
def test_coverage_is_a_share_and_never_more_than_the_arcs(azimuths_deg: list[float]) -> None:
    coverage = azimuth_coverage(rays_at(azimuths_deg))
    assert 0.0 < coverage <= 1.0
    assert coverage <= len(azimuths_deg) * COVERAGE_ARC_DEG / 360.0 + 1e-9


def evidence(place_id: int, room: str, azimuths_deg: np.ndarray) -> PlaceEvidence:
    """A place whose inliers lie at ``azimuths_deg`` in the query."""
    n = len(azimuths_deg)
    pairs = np.column_stack([np.arange(n), np.arange(n)]).astype(np.int64)
    coverage = azimuth_coverage(rays_at(azimuths_deg))
    return PlaceEvidence(place_id, room, n, n, 0.0, pairs, coverage)


def test_a_room_seen_through_a_door_does_not_outweigh_the_room_around() -> None:
    # a bedroom query at its door: the living room's one place gives 65 inliers in the door's
    # 50 degrees, the bedroom's own place 20 all round (the sparse house map's case)
    rooms = ("bedroom", "living")
    places = [
        evidence(1, "living", np.linspace(150.0, 200.0, 65)),
        evidence(2, "bedroom", np.linspace(0.0, 342.0, 20)),
    ]
    assert room_inliers(places, rooms, count="inliers").tolist() == [20.0, 65.0]
    raw = room_likelihood(places, rooms, RatioLikelihood(count="inliers"))
    spread = room_likelihood(places, rooms, RatioLikelihood(count="spread"))
    assert raw[1] > 10 * raw[0]  # the raw count is sure of the living room
    assert spread[0] > spread[1]


def test_a_stored_model_without_a_count_reads_raw_inliers() -> None:
    stored = RatioLikelihood().to_json()
    del stored["count"]
    assert RatioLikelihood.from_json(stored).count == "inliers"
    assert RatioLikelihood.from_json(RatioLikelihood().to_json()).count == "spread"


def test_an_unknown_count_is_refused() -> None:
    with pytest.raises(ValueError, match="count must be one of"):
        RatioLikelihood(count="votes")
