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
    pairs = matcher.knnMatch(
        np.ascontiguousarray(query, np.float32), np.ascontiguousarray(reference, np.float32), k=2
    )
    kept = [
        (first.queryIdx, first.trainIdx, first.distance)
        for first, second in (p for p in pairs if len(p) == 2)
        if first.distance < ratio * second.distance
    ]
    if not kept:
        return np.zeros((0, 2), dtype=np.int64)
    rows = np.array(kept)
    # Keep, for each reference row, only its closest query row.
    order = np.lexsort((rows[:, 2], rows[:, 1]))
    rows = rows[order]
    first_of_reference = np.r_[True, rows[1:, 1] != rows[:-1, 1]]
    unique = rows[first_of_reference, :2].astype(np.int64)
    return unique[np.argsort(unique[:, 0], kind="stable")]
