"""Pan-tilt stitching (thesis 5.2) on sweeps with a known truth, cut from the shipped real photos.

For each 360° photo of ``robot/data/photos`` (17 Poly Haven rooms), a pan-tilt unit's sweep is
simulated: 12 level pinhole photos (320 x 240, focal 240 px) nominally 30° apart, each pan off
by a normal error of ``--yaw-sd-deg`` (1.5° by default; the first photo is the reference).
``robot.pan_stitching.stitch_cylinder`` stitches them; the table gives, per room, how many of
the 12 pairwise shifts were accepted by the voting rules, and the largest error of the stitched
photo positions against the truth, next to the error of the default shift alone (px).

    python benchmarks/bench_pan_stitching.py [--yaw-sd-deg 1.5] [--seed 0]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2
import numpy as np

from robot.pan_stitching import stitch_cylinder, view_from_equirect

PHOTOS = Path(__file__).resolve().parents[1] / "robot" / "data" / "photos"
FOCAL_PX, SIZE_PX, STEP_DEG, N_PHOTOS = 240.0, (320, 240), 30.0, 12


def measure(photo: Path, yaw_error_deg: np.ndarray) -> tuple[int, float, float, float]:
    """``(accepted pairs, max stitched error px, max default error px, seconds)``."""
    equirect = cv2.imread(str(photo))
    if equirect is None:
        raise SystemExit(f"{photo}: not readable")
    yaws_deg = np.arange(N_PHOTOS) * STEP_DEG + yaw_error_deg
    photos = [view_from_equirect(equirect, y, SIZE_PX, FOCAL_PX) for y in yaws_deg]
    start = time.perf_counter()
    stitched = stitch_cylinder(photos, FOCAL_PX, STEP_DEG)
    seconds = time.perf_counter() - start
    true_px = np.radians(yaws_deg) * FOCAL_PX
    default_px = np.radians(np.arange(N_PHOTOS) * STEP_DEG) * FOCAL_PX
    stitched_error = float(np.abs(np.array(stitched.positions_px) - true_px).max())
    default_error = float(np.abs(default_px - true_px).max())
    accepted = sum(shift.accepted for shift in stitched.shifts)
    return accepted, stitched_error, default_error, seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--yaw-sd-deg", type=float, default=1.5)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    print(f"{'room':32s} accepted  stitched px  default px     s")
    within = 0
    photos = sorted(PHOTOS.glob("*.jpg"))
    for photo in photos:
        yaw_error = rng.normal(0.0, args.yaw_sd_deg, N_PHOTOS)
        yaw_error[0] = 0.0
        accepted, stitched_px, default_px, seconds = measure(photo, yaw_error)
        within += stitched_px <= 0.5
        name = photo.stem.removesuffix("_1k")
        print(f"{name:32s} {accepted:4d}/12 {stitched_px:12.1f} {default_px:11.1f} {seconds:5.2f}")
    print(f"stitched within 0.5 px of the truth: {within} of {len(photos)} rooms")


if __name__ == "__main__":
    main()
