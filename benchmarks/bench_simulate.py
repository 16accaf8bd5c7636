"""Benchmark: the whole thesis simulation (every table, both methods) and one ALV.

Run: ``python benchmarks/bench_simulate.py [--runs 20] [--jobs 2]``. Prints wall time of
``toploc simulate --experiment all`` (the target is under 2 minutes on 2 cores) and the cost of
one ALV over 1,000 bearings.
"""

from __future__ import annotations

import argparse
import os
import time
import timeit

import numpy as np

from homing.alv import alv_from_bearings
from homing.thesis.experiments import EXPERIMENTS
from toploc.evaluation.simulation import run_simulation


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    args = parser.parse_args()

    bearings = np.random.default_rng(0).uniform(-np.pi, np.pi, 1000)
    repeats = 2000
    alv_us = 1e6 * timeit.timeit(lambda: alv_from_bearings(bearings), number=repeats) / repeats

    start = time.perf_counter()
    rows = run_simulation(list(EXPERIMENTS), runs=args.runs, jobs=args.jobs).rows
    wall_s = time.perf_counter() - start

    print(f"{'measure':<52} {'value':>12}")
    print(f"{'ALV of 1,000 bearings (us)':<52} {alv_us:>12.1f}")
    label = f"simulate --experiment all, {len(rows)} rows, {args.jobs} jobs (s)"
    print(f"{label:<52} {wall_s:>12.1f}")


if __name__ == "__main__":
    main()
