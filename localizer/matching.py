"""Descriptor matching with Lowe's ratio test: which keypoints of two fingerprints are the same.

The one place that pairs descriptors; the evidence (essential-matrix verification), homing on
images and the compass all start from :func:`match_descriptors`.
"""

from __future__ import annotations

import cv2
import numpy as np

DEFAULT_RATIO = 0.8


def match_descriptors(
    query: np.ndarray, reference: np.ndarray, ratio: float = DEFAULT_RATIO
) -> np.ndarray:
    """Index pairs ``(k, 2)`` int64 ``[query_row, reference_row]`` passing the ratio test.

    ``query`` (n, d) and ``reference`` (m, d) are float32 descriptors (SIFT: d = 128). A query
    row is kept when its nearest reference row is closer than ``ratio`` times the second
    nearest (L2), and only if no other query row claims the same reference row (cross-check on
    the kept pairs, so a repeated texture cannot vote twice). Fewer than two reference rows, or
    an empty side, give no matches.
    """
    if not 0 < ratio <= 1:
        raise ValueError(f"ratio must be in (0, 1], got {ratio}")
    if query.ndim != 2 or reference.ndim != 2 or query.shape[1] != reference.shape[1]:
        raise ValueError(
            f"descriptors must be 2-D with equal widths, got {query.shape} and {reference.shape}"
        )
    if len(query) == 0 or len(reference) < 2:
        return np.zeros((0, 2), dtype=np.int64)
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    found = matcher.knnMatch(
        np.ascontiguousarray(query, np.float32), np.ascontiguousarray(reference, np.float32), k=2
    )
    kept = [
        (first.queryIdx, first.trainIdx, first.distance)
        for first, second in (p for p in found if len(p) == 2)
        if first.distance < ratio * second.distance
    ]
    return _closest_claims(np.array(kept).reshape(-1, 3))


def ratio_test_pairs(nearest: np.ndarray, distances: np.ndarray, ratio: float) -> np.ndarray:
    """:func:`match_descriptors`' ratio test and cross-check on neighbours found elsewhere (an
    approximate search): ``nearest`` (n, 2) int, each query row's two nearest reference rows
    (-1: not found), at L2 ``distances`` (n, 2)."""
    kept = np.flatnonzero((nearest[:, 1] >= 0) & (distances[:, 0] < ratio * distances[:, 1]))
    return _closest_claims(np.column_stack([kept, nearest[kept, 0], distances[kept, 0]]))


def _closest_claims(rows: np.ndarray) -> np.ndarray:
    """From ``rows`` (k, 3) ``[query_row, reference_row, distance]`` in query-row order, the
    pairs ``(m, 2)`` int64 whose query row is the closest to its reference row (ties: the first
    row), sorted by query row."""
    if len(rows) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    order = np.lexsort((rows[:, 2], rows[:, 1]))  # stable: equal distances keep row order
    rows = rows[order]
    first_of_reference = np.r_[True, rows[1:, 1] != rows[:-1, 1]]
    unique = rows[first_of_reference, :2].astype(np.int64)
    return unique[np.argsort(unique[:, 0], kind="stable")]
