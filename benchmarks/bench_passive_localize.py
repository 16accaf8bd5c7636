"""Benchmark: passive localizations, as a client asks the service again and again.

A ROS 2 node calling ``/toploc/localize`` in a loop, on the demo's map (rendered
``building``, built in ``~/.cache/toploc`` first if it is missing), or with ``--db PATH
--world-seed S`` on another map of the ``building`` world rendered from seed ``S`` (a map
recorded by ``benchmarks/bench_recorded_maps.py``, say); the service's runner
(:class:`toploc.runner.LocalizationRunner`) answers each request with one frame.

- ``still``: the robot is kidnapped (seeded, as ``toploc sim kidnap``) into each of the two
  look-alike offices and stays there; ``--requests`` requests each. Frames carry the robot's
  odometry, so frames from one spot count once (``localizer.localizer.SAME_VIEW_M``); with
  ``--no-odometry`` the robot gives none (a camera alone on the bus), and the images say
  whether two frames were taken on one spot (``localizer.visual_homing.same_spot``).
  Prints, per request, how many answers were ``localized``, how many of those named the
  wrong office, and the mean probability of the top room.
- ``walk``: the robot stops in the kitchen twice, the corridor twice, the seminar room, the
  storage room, the corridor and office_b, each stop at a seeded random spot of its room and
  2 m on by odometry from the one before, and is asked once at each stop. Prints the five
  outcomes over all stops (right and localized, right but ambiguous, wrong and localized,
  wrong and ambiguous, lost) and the stops whose answer was wrong and localized. With
  ``--no-doors`` the map's room graph is left out, as a map built from photos has none;
  ``--no-odometry`` as above; ``--anywhere P``: the share of the belief a passive frame of a
  new view spreads over every room (``LocalizerConfig.passive_anywhere_probability``).

Run: ``python benchmarks/bench_passive_localize.py still [--trials 10] [--requests 8]
[--no-odometry]`` or ``python benchmarks/bench_passive_localize.py walk [--trials 10]
[--no-doors] [--no-odometry] [--anywhere P]``. The
code before session 28 is measured by running this file with that code first on
``PYTHONPATH``.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from localizer.loaded_map import LoadedMap
from localizer.localizer import Localizer, LocalizerConfig
from localizer.robot_protocol import Capture, MoveResult, Pose2D, Robot
from mapdb.loading import load_snapshot
from robot.worlds import make_world
from toploc.evaluation.localization import QueryOutcome, count_outcomes, outcome_of
from toploc.maps import ensure_world_map, kidnapped_robot
from toploc.runner import LocalizationRunner

OFFICES = ("office_a", "office_b")
WALK = ("kitchen", "kitchen", "corridor", "corridor", "seminar", "storage", "corridor", "office_b")
STOP_M = 2.0  # odometric metres between two stops of the walk


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


class Walk:
    """A robot that captures at its stops in turn (one robot standing at each) and whose
    odometry says it went ``STOP_M`` on at each; it does not drive."""

    def __init__(self, stops: Sequence[Robot]) -> None:
        self.stops = stops
        self.at = -1

    def capture(self) -> Capture:
        self.at += 1
        return self.stops[self.at].capture()

    def move(self, turn_rad: float, forward_m: float) -> MoveResult:
        raise RuntimeError("a passive walk does not drive")

    def odometry(self) -> Pose2D:
        return Pose2D(STOP_M * self.at, 0.0, 0.0)

    def stop(self) -> None:
        pass


def still(loaded: LoadedMap, args: argparse.Namespace) -> None:
    db, world = args.db, make_world("building", args.world_seed)
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
    print(f"{trials} robots standing still in the map's two offices, {odometry}")
    print(f"{'request':>8} {'localized':>10} {'of them wrong':>14} {'mean top p':>11}")
    for k in range(args.requests):
        print(f"{k + 1:>8} {localized[k]:>10} {wrong[k]:>14} {top_p[k] / trials:>11.3f}")


def walk(loaded: LoadedMap, args: argparse.Namespace) -> None:
    db, world = args.db, make_world("building", args.world_seed)
    config = LocalizerConfig()  # (no keyword: the code before session 28 runs this too)
    if args.anywhere is not None:
        config = LocalizerConfig(passive_anywhere_probability=args.anywhere)
    outcomes, sure_and_wrong = [], []
    for seed in range(args.trials):
        stops = [kidnapped_robot(world, room, 100 * seed + i, db) for i, room in enumerate(WALK)]
        walker: Robot = Walk(stops)
        if args.no_odometry:
            walker = WithoutOdometry(walker)
        runner = LocalizationRunner(Localizer(loaded, config), walker)
        for i, room in enumerate(WALK):
            belief = runner.localize(active=False)
            top = max(belief["rooms"], key=belief["rooms"].get)
            query = QueryOutcome(
                f"walk {seed} stop {i + 1} in {room}",
                room,
                top,
                belief["rooms"][top],
                belief["state"],
                {},
            )
            outcomes.append(outcome_of(query, loaded.rooms))
            if outcomes[-1] == "wrong_localized":
                sure_and_wrong.append(f"{query.image}: {top}")
    doors = "without its doors" if args.no_doors else "with its doors"
    odometry = "without odometry" if args.no_odometry else "with odometry"
    print(
        f"{args.trials} walks of {len(WALK)} stops ({' > '.join(WALK)}), one request each; "
        f"the map {doors}; {odometry}"
    )
    print(", ".join(f"{name} {n}" for name, n in count_outcomes(outcomes).items()))
    for line in sure_and_wrong:
        print("  wrong and localized:", line)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("scenario", choices=("still", "walk"))
    parser.add_argument("--trials", type=int, default=10, help="robots per office, or walks")
    parser.add_argument("--requests", type=int, default=8, help="still: requests per robot")
    parser.add_argument("--no-odometry", action="store_true", help="a robot without")
    parser.add_argument("--no-doors", action="store_true", help="walk: a map without its graph")
    parser.add_argument(
        "--anywhere",
        type=float,
        help="walk: the share of the belief spread over every room (default: the config's)",
    )
    parser.add_argument("--db", type=Path, help="a map of the building world (default: the demo's)")
    parser.add_argument(
        "--world-seed", type=int, default=0, help="the seed --db's world was built from"
    )
    args = parser.parse_args()
    logging.getLogger("toploc.runner").setLevel(logging.ERROR)  # each robot's missing odometry
    args.db = args.db or ensure_world_map("building")
    loaded = LoadedMap.from_snapshot(load_snapshot(args.db))
    if args.no_doors:
        loaded = dataclasses.replace(loaded, edges=())
    (still if args.scenario == "still" else walk)(loaded, args)


if __name__ == "__main__":
    main()
