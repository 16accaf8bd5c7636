"""Unit bearing rays of panorama keypoints, in the robot frame (REP-103: x forward, y left, z up).

A keypoint at azimuth ``b`` (CCW from the heading, see :mod:`homing.bearings`) and elevation
``e`` (positive up) has the unit ray ``(cos e cos b, cos e sin b, sin e)``. The elevation comes
from the keypoint's row through the panorama's camera model (:mod:`homing.cameras`: a
cylinder or an equirectangular sphere), which each fingerprint carries (``Fingerprint.camera``).
These rays are what the essential-matrix verification (:mod:`localizer.verification`) consumes.
"""

from __future__ import annotations

import numpy as np

from homing.cameras import CameraModel, rays_from_angles
from mapdb.records import Fingerprint, FingerprintTable


def rays_from_keypoints(
    keypoints_xy: np.ndarray, bearings_rad: np.ndarray, camera: CameraModel
) -> np.ndarray:
    """(n, 3) unit rays from stored bearings (rad) and the rows of ``keypoints_xy`` (px)."""
    xy = np.asarray(keypoints_xy, dtype=np.float64).reshape(-1, 2)
    return rays_from_angles(bearings_rad, camera.elevation_rad(xy[:, 1]))


def rays_from_fingerprint(fp: Fingerprint) -> np.ndarray:
    """(n, 3) float64 unit rays (robot frame, REP-103) of the keypoints of ``fp`` through its
    own camera (``fp.camera``), row ``i`` for keypoint ``i``; an empty fingerprint gives shape
    (0, 3)."""
    return rays_from_keypoints(fp.keypoints_xy, fp.bearings_rad, fp.camera)


def rays_from_table(table: FingerprintTable) -> np.ndarray:
    """(N, 3) float64 unit rays of every stacked keypoint of ``table``, each place through its
    own camera (``table.cameras``); row ``r`` for the table's row ``r``."""
    rays = np.zeros((len(table.bearings_rad), 3))
    for i, camera in enumerate(table.cameras):
        rows = table.rows(i)
        rays[rows] = rays_from_keypoints(table.keypoints_xy[rows], table.bearings_rad[rows], camera)
    return rays


def triangulated_depths(
    rotated_place: np.ndarray, rays_query: np.ndarray, translation_dir: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Depths ``(d_place, d_query)`` (units of the baseline) of the closest approach of the
    rays ``d_place * rotated_place + t`` and ``d_query * rays_query`` (query frame; the place
    rays already rotated into it): the least-squares solution of
    ``d_place * a - d_query * c = -t``. Parallel rays get depth 0 (no triangulation)."""
    k = np.einsum("ij,ij->i", rotated_place, rays_query)
    a_t = rotated_place @ translation_dir
    c_t = rays_query @ translation_dir
    det = 1.0 - k**2
    ok = det > 1e-9
    safe = np.where(ok, det, 1.0)
    d_place = np.where(ok, (k * c_t - a_t) / safe, 0.0)
    d_query = np.where(ok, (c_t - k * a_t) / safe, 0.0)
    return d_place, d_query
