"""Benchmark: a client asks the service again and again where a robot standing still is.

The robot is kidnapped (seeded, as ``toploc sim kidnap``) into each of the demo map's two
look-alike offices and stays there; the service's runner (:class:`toploc.runner.
LocalizationRunner`) answers ``--requests`` passive ``localize`` requests, as a ROS 2 client
calling ``/toploc/localize`` in a loop would send them. Each frame carries the robot's
odometry, so frames from one spot count once (``localizer.localizer.SAME_VIEW_M``); with
``--no-odometry`` the robot gives none (a camera alone on the bus), and every frame adds its
evidence, as every passive request did before session 28.

Prints, per request, how many answers were ``localized`` and how many of those named the
wrong office, and the mean probability of the top room.

Run: ``python benchmarks/bench_passive_repeats.py [--trials 10] [--requests 4] [--no-odometry]``
(builds the demo's map in ``~/.cache/toploc`` first if it is missing).
"""

from __future__ import annotations

import argparse
import logging

import numpy as np

from localizer.localizer import LoadedMap, Localizer
from localizer.robot_protocol import Capture, MoveResult, Pose2D, Robot
from mapdb.loading import load_snapshot
from robot.worlds import make_world
from toploc.maps import ensure_world_map, kidnapped_robot
from toploc.runner import LocalizationRunner

OFFICES = ("office_a", "office_b")


class WithoutOdometry:
    """``robot`` without odometry: its odometry query fails, as a camera's alone would."""

    def __init__(self, robot: Robot) -> None:
        self.robot = robot

    def capture(self) -> Capture:
        return self.robot.capture()

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        return self.robot.move(turn_rad, forward_m)

    def odometry(self) -> Pose2D:
        raise TimeoutError("this robot gives no odometry")

    def stop(self) -> None:
        self.robot.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=10, help="kidnappings per office")
    parser.add_argument("--requests", type=int, default=4, help="passive requests per trial")
    parser.add_argument("--no-odometry", action="store_true")
    args = parser.parse_args()
    logging.getLogger("toploc.runner").setLevel(logging.ERROR)  # the warning each robot logs

    db = ensure_world_map("building")
    loaded = LoadedMap.from_snapshot(load_snapshot(db))
    world = make_world("building")
    localized = np.zeros(args.requests, dtype=int)
    wrong = np.zeros(args.requests, dtype=int)
    top_p = np.zeros(args.requests)
    for seed in range(args.trials):
        for office in OFFICES:
            robot: Robot = kidnapped_robot(world, office, seed, db)
            if args.no_odometry:
                robot = WithoutOdometry(robot)
            runner = LocalizationRunner(Localizer(loaded), robot)
            for k in range(args.requests):
                belief = runner.localize(active=False)
                top = max(belief["rooms"], key=belief["rooms"].get)
                top_p[k] += belief["rooms"][top]
                if belief["state"] == "localized":
                    localized[k] += 1
                    wrong[k] += top != office
    trials = args.trials * len(OFFICES)
    odometry = "without odometry" if args.no_odometry else "with odometry"
    print(f"{trials} robots standing still in the demo map's offices, {odometry}")
    print(f"{'request':>8} {'localized':>10} {'of them wrong':>14} {'mean top p':>11}")
    for k in range(args.requests):
        print(f"{k + 1:>8} {localized[k]:>10} {wrong[k]:>14} {top_p[k] / trials:>11.3f}")


if __name__ == "__main__":
    main()
