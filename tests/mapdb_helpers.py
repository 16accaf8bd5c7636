"""Helpers for the map database tests: synthetic fingerprints, images and consistency checks."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import cv2
import numpy as np

from mapdb.records import Fingerprint, NewPlace


def make_fingerprint(
    rng: np.random.Generator,
    detector: str = "sift",
    n: int = 10,
    dim: int = 128,
    sizes: bool = True,
) -> Fingerprint:
    """A random fingerprint of ``n`` keypoints on a 360 x 40 px panorama; with random keypoint
    sizes (2-40 px), or none known (``sizes=False``: a place stored before schema 5)."""
    xy = rng.uniform([0, 0], [359, 39], size=(n, 2)).astype(np.float32)
    return Fingerprint(
        detector=detector,
        image_width_px=360,
        image_height_px=40,
        keypoints_xy=xy,
        bearings_rad=np.angle(np.exp(-2j * np.pi * xy[:, 0].astype(np.float64) / 360)),
        descriptors=rng.random((n, dim), dtype=np.float32),
        params={"detector": detector, "max_keypoints": 2000, "band_deg": 20.0},
        keypoint_sizes_px=rng.uniform(2.0, 40.0, n).astype(np.float32) if sizes else None,
    )


def new_place(room: str, index: int) -> NewPlace:
    """A place whose image hash is derived from ``index`` (unique per index)."""
    return NewPlace(
        room=room,
        image_sha256=f"{index:064x}",
        source=f"test/{room}/{index}.png",
        x_m=float(index),
        y_m=-1.5,
        heading_deg=90.0,
        captured_utc="2024-01-01T00:00:00+00:00",
    )


def write_image(path: Path, seed: int, size_px: tuple[int, int] = (96, 24)) -> Path:
    """A random grey PNG of ``size_px`` (width, height)."""
    image = np.random.default_rng(seed).integers(0, 256, (size_px[1], size_px[0]), np.uint8)
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), image)
    return path


def table_counts(path: Path) -> dict[str, int]:
    """Row counts of the map tables, read with a plain sqlite3 connection."""
    with sqlite3.connect(path) as conn:
        return {
            table: conn.execute(f"SELECT COUNT(*) FROM {table}").fetchone()[0]
            for table in ("rooms", "edges", "places", "fingerprints", "legs")
        }


def assert_consistent(path: Path, detectors: int = 2) -> None:
    """Integrity check passes, no dangling rows, every place has ``detectors`` fingerprints."""
    with sqlite3.connect(path) as conn:
        assert conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        assert conn.execute("PRAGMA foreign_key_check").fetchall() == []
        per_place = conn.execute(
            "SELECT p.id, COUNT(f.id) FROM places p LEFT JOIN fingerprints f "
            "ON f.place_id = p.id GROUP BY p.id"
        ).fetchall()
    assert all(count == detectors for _, count in per_place), per_place
