"""Benchmark: closed-loop visual homing on rendered panoramas, the variants of
:data:`localizer.visual_homing.VARIANTS` ("thesis", "best", "pose").

Run: ``python benchmarks/bench_visual_homing.py [--quick] [--per-run] [--rooms WORLD:ROOM:RUNS,...]
[--variants thesis,best,pose] [--projection cylinder|equirect]``. For each room (by default the
``square`` world's room, ``office_a`` of the ``building`` world and the bare ``living`` room of
the ``house``) the goal is the capture place
nearest the room's centre, photographed at heading 0 like a map panorama; the robot is kidnapped
to seeded random free poses in the room (random headings, 5 % motion noise) and homes with
:func:`localizer.visual_homing.drive_home` on SIFT fingerprints. Prints a markdown table: the
final true distance to the goal, the share of runs ending within 0.3 m, how often the robot
*said* it arrived, the moves made and the true distance driven per metre of start distance.
``--quick``: 512 x 96 panoramas and 3 starts in the square room only. ``--projection
equirect``: 1024 x 512 equirectangular panoramas read as spheres (the floor and ceiling in view,
as a 360° camera sees them); the default is the 1024 x 192 cylinder.
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass

import numpy as np

from localizer.cameras import CameraSpec
from localizer.robot_protocol import Pose2D
from localizer.visual_homing import (
    VARIANTS,
    HomingParams,
    HomingProgress,
    StepParams,
    drive_home,
    grey_extractor,
)
from robot.render import PanoramaCamera
from robot.sim_robot import MotionNoise, SimulatedRobot
from robot.world import World, capture_places
from robot.worlds import make_world

SUCCESS_M = 0.3


@dataclass(frozen=True)
class Run:
    room: str
    variant: str
    seed: int
    start_m: float
    final_m: float
    arrived: bool
    reason: str
    steps: int
    driven_m: float
    wall_s: float
    matched: float  # the last step's matched inliers over the goal's features (NaN: no step)


def goal_pose(world: World, room: str) -> Pose2D:
    """The capture place of ``room`` nearest its centre, heading 0, in the building frame."""
    r = world.room(room)
    centre = (r.size_m[0] / 2, r.size_m[1] / 2)
    places = [p for p in capture_places(world) if p.room == room]
    best = min(places, key=lambda p: math.hypot(p.x_m - centre[0], p.y_m - centre[1]))
    return world.building_pose(room, Pose2D(best.x_m, best.y_m, 0.0))


def run_room(
    world: World, room: str, seeds: range, camera: PanoramaCamera, variant: str
) -> list[Run]:
    extract = grey_extractor("sift", CameraSpec() if camera.projection == "equirect" else None)
    goal = goal_pose(world, room)
    goal_fp = extract(SimulatedRobot(world, goal, camera=camera, grey=True).capture().image)
    params = HomingParams(step=StepParams(variant))  # type: ignore[arg-type]
    runs = []
    for seed in seeds:
        robot = SimulatedRobot.kidnapped(
            world, room, seed=seed, camera=camera, grey=True, noise=MotionNoise(0.05, 0.05)
        )
        start = robot.true_pose
        t0 = time.perf_counter()
        last = [math.nan]

        def record(progress: HomingProgress, last: list[float] = last) -> None:
            if progress.home is not None:
                last[0] = progress.home.n_used / max(goal_fp.n, 1)

        result = drive_home(robot, goal_fp, extract, params, record)
        end = robot.true_pose
        runs.append(
            Run(
                room,
                variant,
                seed,
                math.hypot(start.x_m - goal.x_m, start.y_m - goal.y_m),
                math.hypot(end.x_m - goal.x_m, end.y_m - goal.y_m),
                result.arrived,
                result.reason,
                result.steps,
                robot.distance_driven_m,
                time.perf_counter() - t0,
                last[0],
            )
        )
    return runs


def summary_row(runs: list[Run]) -> str:
    final = np.array([r.final_m for r in runs])
    ratio = np.array([r.driven_m / max(r.start_m, 1e-9) for r in runs])
    return (
        f"| {runs[0].room} | {runs[0].variant} | {len(runs)} "
        f"| {np.median([r.start_m for r in runs]):.2f} | {np.median(final):.2f} "
        f"| {final.max():.2f} | {np.mean(final < SUCCESS_M):.0%} "
        f"| {sum(r.arrived for r in runs)}/{len(runs)} | {np.median([r.steps for r in runs]):.0f} "
        f"| {np.median(ratio):.2f} | {np.mean([r.wall_s for r in runs]):.1f} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="512 x 96, 3 starts, square only")
    parser.add_argument("--per-run", action="store_true", help="also print every run")
    parser.add_argument(
        "--rooms",
        default="square:square:10,building:office_a:4,house:living:6",
        help="WORLD:ROOM:RUNS, comma-separated",
    )
    parser.add_argument("--variants", default=",".join(VARIANTS))
    parser.add_argument("--projection", choices=("cylinder", "equirect"), default="cylinder")
    args = parser.parse_args()
    if args.quick:
        camera = PanoramaCamera(512, 96)
    elif args.projection == "equirect":
        camera = PanoramaCamera(1024, 512, projection="equirect")
    else:
        camera = PanoramaCamera(1024, 192)
    rooms = [(w, r, range(int(n))) for w, r, n in (x.split(":") for x in args.rooms.split(","))]
    if args.quick:
        rooms = [("square", "square", range(3))]
    runs: list[list[Run]] = []
    for world_name, room, seeds in rooms:
        world = make_world(world_name, 0)
        for variant in args.variants.split(","):
            runs.append(run_room(world, room, seeds, camera, variant))
    print(f"Visual homing, {camera.width_px}x{camera.height_px}, SIFT, 5 % motion noise\n")
    print(
        "| room | variant | runs | start m (median) | final m (median) | final m (max) "
        f"| within {SUCCESS_M} m | said arrived | moves (median) | driven / start (median) "
        "| s per run |"
    )
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for group in runs:
        print(summary_row(group))
    if args.per_run:
        print(
            "\n| room | variant | seed | start m | final m | reason | moves | driven m "
            "| last matched % of goal |"
        )
        print("| --- | --- | ---: | ---: | ---: | --- | ---: | ---: | ---: |")
        for group in runs:
            for r in group:
                print(
                    f"| {r.room} | {r.variant} | {r.seed} | {r.start_m:.2f} | {r.final_m:.2f} "
                    f"| {r.reason} | {r.steps} | {r.driven_m:.2f} | {100 * r.matched:.0f} |"
                )


if __name__ == "__main__":
    main()
