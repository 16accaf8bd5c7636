"""Unit bearing rays of panorama keypoints, in the robot frame (REP-103: x forward, y left, z up).

A keypoint at azimuth ``b`` (CCW from the heading, see :mod:`homing.bearings`) and elevation
``e`` (positive up) has the unit ray ``(cos e cos b, cos e sin b, sin e)``. The elevation comes
from the keypoint's row on the cylinder (:func:`localizer.panorama.elevation_rad_from_row`): focal
length ``W / (2*pi)`` px and the horizon at the middle row unless the cylinder says otherwise.
These rays are what the essential-matrix verification (:mod:`localizer.verification`) consumes.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike

from localizer.panorama import Cylinder, elevation_rad_from_row
from mapdb.records import Fingerprint, FingerprintTable, ParamValue


def rays_from_angles(bearing_rad: ArrayLike, elevation_rad: ArrayLike) -> np.ndarray:
    """(n, 3) float64 unit rays in the robot frame from azimuths and elevations (rad)."""
    b = np.asarray(bearing_rad, dtype=np.float64).reshape(-1)
    e = np.asarray(elevation_rad, dtype=np.float64).reshape(-1)
    if b.shape != e.shape:
        raise ValueError(f"{b.shape[0]} bearings but {e.shape[0]} elevations")
    cos_e = np.cos(e)
    return np.stack([cos_e * np.cos(b), cos_e * np.sin(b), np.sin(e)], axis=1)


def cylinder_from_params(
    width_px: int, height_px: int, params: Mapping[str, ParamValue]
) -> Cylinder:
    """The cylinder of a ``width_px`` x ``height_px`` panorama, with the ``focal_px`` and
    ``horizon_row_px`` recorded in its extraction ``params`` when present (else the defaults)."""
    focal = params.get("focal_px")
    horizon = params.get("horizon_row_px")
    return Cylinder(
        int(width_px),
        int(height_px),
        None if focal is None else float(focal),
        None if horizon is None else float(horizon),
    )


def cylinder_of(fingerprint: Fingerprint) -> Cylinder:
    """The cylinder a fingerprint was extracted on (see :func:`cylinder_from_params`)."""
    return cylinder_from_params(
        fingerprint.image_width_px, fingerprint.image_height_px, fingerprint.params
    )


def rays_from_keypoints(
    keypoints_xy: np.ndarray, bearings_rad: np.ndarray, cylinder: Cylinder
) -> np.ndarray:
    """(n, 3) unit rays from stored bearings (rad) and the rows of ``keypoints_xy`` (px)."""
    xy = np.asarray(keypoints_xy, dtype=np.float64).reshape(-1, 2)
    return rays_from_angles(bearings_rad, elevation_rad_from_row(xy[:, 1], cylinder))


def rays_from_fingerprint(fp: Fingerprint, cylinder: Cylinder | None = None) -> np.ndarray:
    """(n, 3) float64 unit rays (robot frame, REP-103) of the keypoints of ``fp``, row ``i`` for
    keypoint ``i``. ``cylinder`` defaults to :func:`cylinder_of` ``(fp)``; an empty fingerprint
    gives shape (0, 3)."""
    cylinder = cylinder_of(fp) if cylinder is None else cylinder
    if cylinder.width_px != fp.image_width_px or cylinder.height_px != fp.image_height_px:
        raise ValueError(
            f"cylinder is {cylinder.width_px}x{cylinder.height_px} px but the fingerprint's "
            f"panorama is {fp.image_width_px}x{fp.image_height_px} px"
        )
    return rays_from_keypoints(fp.keypoints_xy, fp.bearings_rad, cylinder)


def rays_from_table(table: FingerprintTable) -> np.ndarray:
    """(N, 3) float64 unit rays of every stacked keypoint of ``table``, each place on its own
    cylinder (its image size and extraction parameters); row ``r`` for the table's row ``r``."""
    rays = np.zeros((len(table.bearings_rad), 3))
    for i in range(len(table.place_ids)):
        rows = table.rows(i)
        width, height = table.image_sizes_px[i]
        cylinder = cylinder_from_params(width, height, table.params[i])
        rays[rows] = rays_from_keypoints(
            table.keypoints_xy[rows], table.bearings_rad[rows], cylinder
        )
    return rays
