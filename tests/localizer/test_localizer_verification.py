"""Rays from fingerprints and essential-matrix verification on synthetic rays with known R, t."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from homing.bearings import wrap_angle_rad
from homing.cameras import Cylinder, rays_from_angles
from localizer.verification import (
    Verification,
    VerificationParams,
    home_direction_rad,
    tangent_sampson_error_rad,
    verify,
    yaw_from_rotation,
)
from mapdb.records import Fingerprint


def rz(yaw_rad: float) -> np.ndarray:
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def two_views(
    rng: np.random.Generator,
    n: int,
    yaw_rad: float,
    t_query_in_place_m: np.ndarray,
    n_outliers: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rays of ``n`` room points seen from the place (origin) and from the query, whose frame is
    the place's turned by ``yaw_rad`` and moved to ``t_query_in_place_m``; the first
    ``n_outliers`` query rays are replaced by random directions. Returns rays and the pairs."""
    points = np.column_stack(
        [rng.uniform(-4, 4, n), rng.uniform(-4, 4, n), rng.uniform(-1.0, 1.5, n)]
    )
    points[np.linalg.norm(points[:, :2], axis=1) < 0.8, :2] *= 3.0  # keep points off the camera
    place = points / np.linalg.norm(points, axis=1, keepdims=True)
    in_query = (points - t_query_in_place_m) @ rz(yaw_rad)  # R_place_from_query^T (p - t)
    query = in_query / np.linalg.norm(in_query, axis=1, keepdims=True)
    random = rng.normal(size=(n_outliers, 3))
    query[:n_outliers] = random / np.linalg.norm(random, axis=1, keepdims=True)
    pairs = np.column_stack([np.arange(n), np.arange(n)])
    return query, place, pairs


def test_exact_inliers_outliers_rejected_yaw_recovered() -> None:
    rng = np.random.default_rng(3)
    query, place, pairs = two_views(rng, 200, 0.6, np.array([0.7, -0.4, 0.0]), n_outliers=60)
    result = verify(query, place, pairs, VerificationParams(seed=1))
    kept = set(result.inlier_pairs[:, 0].tolist())
    assert set(range(60, 200)) <= kept  # every true pair
    assert len(kept & set(range(60))) <= 3  # random directions: at most a chance few
    assert result.inliers == len(result.inlier_pairs)
    assert abs(wrap_angle_rad(result.yaw_rad - 0.6)) < 1e-6
    np.testing.assert_allclose(result.rotation, rz(0.6).T, atol=1e-6)
    # translation_dir is the query-frame direction of cam2_from_cam1: -R^T t_query_in_place.
    expected_t = -(rz(0.6).T @ np.array([0.7, -0.4, 0.0]))
    np.testing.assert_allclose(
        result.translation_dir, expected_t / np.linalg.norm(expected_t), atol=1e-6
    )


@pytest.mark.parametrize(
    ("yaw_rad", "query_in_place_m"),
    [(0.0, (1.0, 0.0)), (0.0, (0.0, -1.2)), (1.2, (-0.8, 0.5)), (-2.5, (1.5, 1.5))],
)
def test_translation_dir_points_from_the_query_to_the_place(
    yaw_rad: float, query_in_place_m: tuple[float, float]
) -> None:
    """The sign convention: ``+translation_dir`` (not its negative) is the home direction from
    the query to the place, in the query's robot frame (REP-103, CCW from its heading)."""
    t_query = np.array([*query_in_place_m, 0.0])
    query, place, pairs = two_views(np.random.default_rng(2), 80, yaw_rad, t_query)
    result = verify(query, place, pairs, VerificationParams(seed=0))
    to_place_in_place = -t_query  # the place is the origin of its own frame
    to_place_in_query = rz(yaw_rad).T @ to_place_in_place
    expected = np.arctan2(to_place_in_query[1], to_place_in_query[0])
    assert abs(wrap_angle_rad(home_direction_rad(result) - expected)) < 1e-6
    # the same pair seen the other way round: from the place to the query, in the place's frame
    back = result.swapped()
    expected_back = np.arctan2(t_query[1], t_query[0])
    assert abs(wrap_angle_rad(home_direction_rad(back) - expected_back)) < 1e-6
    assert abs(wrap_angle_rad(back.yaw_rad + yaw_rad)) < 1e-6
    np.testing.assert_array_equal(back.inlier_pairs, result.inlier_pairs[:, ::-1])


def test_home_direction_undefined_without_geometry_or_inliers() -> None:
    assert np.isnan(home_direction_rad(Verification.none()))
    rng = np.random.default_rng(4)
    query, place, pairs = two_views(rng, 30, 0.2, np.array([1.0, 0.0, 0.0]))
    result = verify(query, place, pairs)
    assert np.isfinite(home_direction_rad(result, min_inliers=30))
    assert np.isnan(home_direction_rad(result, min_inliers=31))
    assert Verification.none().swapped().translation_dir is None


def test_pure_rotation_keeps_every_true_pair() -> None:
    """Query at the place itself: pycolmap's cheirality would drop about half; we keep all."""
    rng = np.random.default_rng(5)
    query, place, pairs = two_views(rng, 150, -2.0, np.zeros(3))
    noisy = query + rng.normal(0.0, 0.001, query.shape)
    result = verify(noisy, place, pairs, VerificationParams(seed=2))
    assert result.inliers >= 145
    assert abs(wrap_angle_rad(result.yaw_rad + 2.0)) < np.deg2rad(0.5)


@settings(max_examples=25, deadline=None)
@given(
    yaw_rad=st.floats(-np.pi + 1e-3, np.pi),
    tx=st.floats(-1.5, 1.5),
    ty=st.floats(-1.5, 1.5),
    seed=st.integers(0, 1000),
)
def test_yaw_recovered_for_any_heading_change(
    yaw_rad: float, tx: float, ty: float, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    query, place, pairs = two_views(rng, 60, yaw_rad, np.array([tx, ty, 0.0]))
    result = verify(query, place, pairs, VerificationParams(seed=seed))
    assert result.inliers >= 58
    assert abs(wrap_angle_rad(result.yaw_rad - yaw_rad)) < 1e-4


def test_points_near_the_camera_seen_with_wide_parallax_are_inliers() -> None:
    # Three of these points lie within 1 m of the query, 1.8 m from the place: the two rays of
    # each are more than 90° apart, yet they triangulate in front of both cameras.
    rng = np.random.default_rng(0)
    query, place, pairs = two_views(rng, 60, 0.0, np.array([1.0, -1.5, 0.0]))
    rotated = place  # yaw 0: the place's rays are already in the query's orientation
    assert np.sum(np.einsum("ij,ij->i", rotated, query) <= 0) >= 3
    assert verify(query, place, pairs, VerificationParams(seed=0)).inliers == 60


def test_deterministic_for_a_seed() -> None:
    rng = np.random.default_rng(8)
    query, place, pairs = two_views(rng, 120, 1.0, np.array([0.3, 0.2, 0.0]), n_outliers=70)
    query = query + rng.normal(0.0, 0.003, query.shape)
    a = verify(query, place, pairs, VerificationParams(seed=4))
    b = verify(query, place, pairs, VerificationParams(seed=4))
    assert a.inliers == b.inliers
    np.testing.assert_array_equal(a.inlier_pairs, b.inlier_pairs)
    assert a.yaw_rad == b.yaw_rad


def test_too_few_pairs_and_empty_give_no_geometry() -> None:
    rng = np.random.default_rng(1)
    query, place, pairs = two_views(rng, 7, 0.3, np.array([0.5, 0.0, 0.0]))
    result = verify(query, place, pairs, VerificationParams(min_correspondences=8))
    assert result.inliers == 0 and result.rotation is None and np.isnan(result.yaw_rad)
    empty = verify(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 2), np.int64))
    assert empty.inliers == 0 and empty.inlier_pairs.shape == (0, 2)


def test_degenerate_identical_rays_do_not_raise() -> None:
    rays = np.tile([[1.0, 0.0, 0.0]], (20, 1))
    pairs = np.column_stack([np.arange(20), np.arange(20)])
    result = verify(rays, rays, pairs)
    assert isinstance(result, Verification)
    assert result.inliers in (0, 20)


def test_bad_input_is_named() -> None:
    with pytest.raises(ValueError, match="query_rays must have shape"):
        verify(np.zeros((5, 2)), np.ones((5, 3)), np.zeros((0, 2), np.int64))
    with pytest.raises(ValueError, match="zero-length"):
        verify(np.zeros((5, 3)), np.ones((5, 3)), np.zeros((0, 2), np.int64))
    with pytest.raises(ValueError, match="pairs index outside"):
        verify(np.ones((5, 3)), np.ones((5, 3)), np.array([[0, 5]]))
    with pytest.raises(ValueError, match="min_correspondences"):
        VerificationParams(min_correspondences=4)


def test_sampson_error_is_angular_distance_to_the_epipolar_circle() -> None:
    """Moving a query ray by a small angle off its epipolar great circle gives about that angle
    (the error splits over the two rays, so it lies between angle/sqrt(2) and angle)."""
    t = np.array([1.0, 0.0, 0.0])
    E = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])  # R = I
    place = np.array([[0.0, 1.0, 0.0]])
    angle = 0.004
    query = np.array([[0.0, np.cos(angle), np.sin(angle)]])  # tilted out of the z=0 plane
    err = tangent_sampson_error_rad(E, place, query)[0]
    assert angle / np.sqrt(2) - 1e-6 <= err <= angle + 1e-6


def test_yaw_from_rotation_convention() -> None:
    assert yaw_from_rotation(rz(0.5).T) == pytest.approx(0.5)


def test_a_fingerprints_rays_follow_its_bearings_and_rows() -> None:
    w, h = 360, 41
    xy = np.array([[0.0, 20.0], [90.0, 20.0], [180.0, 0.0], [270.0, 40.0]])
    fp = Fingerprint("sift", w, h, xy, -2 * np.pi * xy[:, 0] / w, np.zeros((4, 128), np.float32))
    rays = fp.rays()
    np.testing.assert_allclose(np.linalg.norm(rays, axis=1), 1.0)
    np.testing.assert_allclose(rays[0], [1.0, 0.0, 0.0], atol=1e-12)  # heading, horizon
    np.testing.assert_allclose(rays[1], [0.0, -1.0, 0.0], atol=1e-12)  # 90° clockwise: right
    f = w / (2 * np.pi)
    assert rays[2, 2] == pytest.approx(np.sin(np.arctan(20.0 / f)))  # top row looks up
    assert rays[3, 2] == pytest.approx(-np.sin(np.arctan(20.0 / f)))
    assert Fingerprint.empty("sift", w, h).rays().shape == (0, 3)
    with pytest.raises(ValueError, match="cylinder camera is 100x41"):
        Fingerprint(
            "sift", w, h, xy, fp.bearings_rad, fp.descriptors, camera_model=Cylinder(100, 41)
        )
    np.testing.assert_allclose(rays_from_angles([np.pi / 2], [0.0]), [[0.0, 1.0, 0.0]], atol=1e-12)


def test_above_floor_keeps_the_matches_whose_rays_both_clear_the_floor_band():
    from homing.cameras import rays_from_angles
    from localizer.verification import above_floor

    elevations_deg = np.array([-40.0, -20.0, 0.0, 30.0])
    rays = rays_from_angles(np.zeros(4), np.radians(elevations_deg))
    matches = np.array([[0, 3], [1, 2], [2, 0], [3, 3]])
    kept = above_floor(rays, rays, matches, min_elevation_deg=-25.0)
    np.testing.assert_array_equal(kept, [[1, 2], [3, 3]])
    assert above_floor(rays, rays, matches[:0]).shape == (0, 2)


def test_cheirality_sign_says_which_way_the_translation_fits() -> None:
    from dataclasses import replace

    from localizer.verification import cheirality_sign

    query, place, pairs = two_views(np.random.default_rng(5), 120, 0.4, np.array([1.0, 0.5, 0.0]))
    result = verify(query, place, pairs, VerificationParams(seed=0))
    assert cheirality_sign(result, query, place) == 1
    flipped = replace(result, translation_dir=-result.translation_dir)
    assert cheirality_sign(flipped, query, place) == -1
    assert cheirality_sign(Verification.none(), query, place) == 0


def test_cheirality_sign_is_counted_above_the_floor() -> None:
    """Floor matches that fit the opposite translation (aliased planks) outnumber the walls'
    but do not set the sign; counted over every elevation they would."""
    from localizer.verification import cheirality_sign

    rng = np.random.default_rng(6)
    t_query = np.array([0.8, -0.3, 0.0])
    n_wall, n_floor = 20, 60
    wall = np.column_stack(
        [rng.uniform(-4, 4, n_wall), rng.choice([-4.0, 4.0], n_wall), rng.uniform(0.0, 1.2, n_wall)]
    )
    floor = np.column_stack(
        [rng.uniform(-2, 2, n_floor), rng.uniform(-2, 2, n_floor), np.full(n_floor, -1.4)]
    )
    floor[np.linalg.norm(floor[:, :2], axis=1) < 0.5, :2] += 1.0

    def rays(points: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        at_place = points / np.linalg.norm(points, axis=1, keepdims=True)
        at_query = points - t
        return at_query / np.linalg.norm(at_query, axis=1, keepdims=True), at_place

    wall_q, wall_p = rays(wall, t_query)
    floor_q, floor_p = rays(floor, -t_query)  # parallax of the wrong sign
    query, place = np.vstack([wall_q, floor_q]), np.vstack([wall_p, floor_p])
    home = -t_query / np.linalg.norm(t_query)  # query frame = place frame here (no yaw)
    pairs = np.column_stack([np.arange(len(query)), np.arange(len(query))])
    truth = Verification(len(query), pairs, 0.0, np.eye(3), home)
    assert cheirality_sign(truth, query, place) == 1
    assert cheirality_sign(truth, query, place, min_elevation_deg=-90.0) == -1


def test_distance_vote_says_which_side_of_the_axis_the_place_lies_on() -> None:
    from dataclasses import replace

    from localizer.verification import distance_vote

    query, place, pairs = two_views(np.random.default_rng(5), 120, 0.4, np.array([1.0, 0.5, 0.0]))
    result = verify(query, place, pairs, VerificationParams(seed=0))
    vote, statistic = distance_vote(result, query, place)
    assert vote == 1 and statistic < -2.0
    flipped = replace(result, translation_dir=-result.translation_dir)
    assert distance_vote(flipped, query, place)[0] == -1


query_poses = given(
    st.floats(-np.pi, np.pi),
    st.floats(0.5, 3.0),
    st.floats(-np.pi, np.pi),
    st.integers(0, 2**32 - 1),
)
"""The query's heading (rad), distance (m) and direction (rad) from the place, and a seed: the
arguments of a property test over poses."""


@settings(max_examples=40, deadline=None)
@query_poses
def test_distance_vote_follows_the_true_translation_whatever_the_pose(
    heading_rad: float, distance_m: float, direction_rad: float, seed: int
) -> None:
    """With exact rays and the true pose (no RANSAC), the elevations side with the truth."""
    from localizer.verification import distance_vote

    t_query = distance_m * np.array([np.cos(direction_rad), np.sin(direction_rad), 0.0])
    query, place, pairs = two_views(np.random.default_rng(seed), 60, heading_rad, t_query)
    home = rz(heading_rad).T @ (-t_query) / distance_m  # the place, in the query's frame
    truth = Verification(len(pairs), pairs, float(heading_rad), rz(heading_rad).T, home)
    assert distance_vote(truth, query, place)[0] == 1


def flat_views(
    rng: np.random.Generator, n: int, yaw_rad: float, t_query_in_place_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Verification]:
    """``n`` points at the cameras' height (on the horizon: their elevations say nothing) seen
    from the place (origin) and the query (as :func:`two_views`): the query's and the place's
    rays, the keypoint sizes (px) a 20 px-metre feature has at each one's distance, and the
    true verification (row ``i`` of each view paired)."""
    points = np.column_stack([rng.uniform(-4, 4, n), rng.uniform(-4, 4, n), np.zeros(n)])
    points[np.linalg.norm(points[:, :2], axis=1) < 0.8, :2] *= 3.0
    in_query = (points - t_query_in_place_m) @ rz(yaw_rad)
    query = in_query / np.linalg.norm(in_query, axis=1, keepdims=True)
    place = points / np.linalg.norm(points, axis=1, keepdims=True)
    sizes_query = 20.0 / np.linalg.norm(in_query, axis=1)
    sizes_place = 20.0 / np.linalg.norm(points, axis=1)
    pairs = np.column_stack([np.arange(n), np.arange(n)])
    home = rz(yaw_rad).T @ (-t_query_in_place_m) / np.linalg.norm(t_query_in_place_m)
    truth = Verification(n, pairs, float(yaw_rad), rz(yaw_rad).T, home)
    return query, place, sizes_query, sizes_place, truth


@settings(max_examples=40, deadline=None)
@query_poses
def test_keypoint_sizes_tell_the_side_where_the_elevations_cannot(
    heading_rad: float, distance_m: float, direction_rad: float, seed: int
) -> None:
    from dataclasses import replace

    from localizer.verification import distance_vote

    t_query = distance_m * np.array([np.cos(direction_rad), np.sin(direction_rad), 0.0])
    query, place, sizes_q, sizes_p, truth = flat_views(
        np.random.default_rng(seed), 40, heading_rad, t_query
    )
    assert distance_vote(truth, query, place) == (0, 0.0)  # on the horizon: no elevations
    assert distance_vote(truth, query, place, sizes_q, sizes_p)[0] == 1
    flipped = replace(truth, translation_dir=-truth.translation_dir)
    assert distance_vote(flipped, query, place, sizes_q, sizes_p)[0] == -1


def test_keypoint_sizes_on_the_floor_are_left_out() -> None:
    """Floor matches that fit the opposite translation (a plank matched to the next one: their
    elevations and sizes say the opposite side) do not outvote the points above the floor."""
    from localizer.verification import distance_vote

    rng = np.random.default_rng(8)
    t_query = np.array([1.5, 0.0, 0.0])
    query, place, sizes_q, sizes_p, truth = flat_views(rng, 20, 0.0, t_query)
    floor = np.column_stack([rng.uniform(-2, 2, 60), rng.uniform(-2, 2, 60), np.full(60, -1.4)])
    floor_q, floor_p = floor + t_query, floor  # seen as if from the query's mirror image
    query = np.vstack([query, floor_q / np.linalg.norm(floor_q, axis=1, keepdims=True)])
    place = np.vstack([place, floor_p / np.linalg.norm(floor_p, axis=1, keepdims=True)])
    sizes_q = np.concatenate([sizes_q, 20.0 / np.linalg.norm(floor_q, axis=1)])
    sizes_p = np.concatenate([sizes_p, 20.0 / np.linalg.norm(floor_p, axis=1)])
    pairs = np.column_stack([np.arange(80), np.arange(80)])
    truth = Verification(80, pairs, 0.0, np.eye(3), truth.translation_dir)
    assert distance_vote(truth, query, place, sizes_q, sizes_p)[0] == 1
    assert distance_vote(truth, query, place, sizes_q, sizes_p, min_elevation_deg=-90.0)[0] == -1


def test_distance_vote_needs_enough_points_that_give_a_distance() -> None:
    from dataclasses import replace

    from localizer.verification import DISTANCE_MIN_INLIERS, distance_vote

    query, place, pairs = two_views(np.random.default_rng(7), 40, 0.0, np.array([1.0, 0.0, 0.0]))
    truth = Verification(len(pairs), pairs, 0.0, np.eye(3), np.array([-1.0, 0.0, 0.0]))
    flat_query, flat_place = query.copy(), place.copy()
    flat_query[:, 2] = flat_place[:, 2] = 0.0  # every point at the camera's height
    assert distance_vote(truth, flat_query, flat_place) == (0, 0.0)
    few = pairs[: DISTANCE_MIN_INLIERS - 1]
    sizes = np.ones(len(query))
    assert distance_vote(
        replace(truth, inliers=len(few), inlier_pairs=few), query, place, sizes, sizes
    ) == (0, 0.0)
    assert distance_vote(Verification.none(), query, place) == (0, 0.0)
