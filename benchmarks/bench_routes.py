"""Benchmark the recorded routes on a big map: building the graph of legs and finding a route.

Makes ``--places`` places recorded on one drive as ``toploc map record --every-m`` records them
(a leg with a position every 0.1 m, 2-6 m between two places, seeded random walk in a
``--site-m`` square: the drive crosses itself often), then times
:func:`localizer.routes.leg_graph` (the legs joined where they pass each other) and
:func:`localizer.routes.route_out` from every hundredth place (up to 15 m, the active
localizer's longest route check).

    python benchmarks/bench_routes.py [--places 1000] [--site-m 60]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from localizer.routes import ROUTE_MAX_M, leg_graph, route_out
from mapdb.records import Leg, Place

TRAIL_STEP_M = 0.1
"""A position kept every this many metres of a leg (``toploc map record``'s)."""


def recorded_drive(n_places: int, site_m: float, seed: int = 0) -> list[Place]:
    """``n_places`` places of rooms of ten places each on one random drive in a square."""
    rng = np.random.default_rng(seed)
    places = [Place(1, "r0", 0.0, 0.0, 0.0)]
    x, y = 0.0, 0.0
    for place_id in range(2, n_places + 1):
        heading, length = rng.uniform(-math.pi, math.pi), rng.uniform(2.0, 6.0)
        trail = []
        for k in range(1, int(length / TRAIL_STEP_M)):
            along = TRAIL_STEP_M * k
            trail.append(
                (
                    float(np.clip(x + along * math.cos(heading), 0.0, site_m)),
                    float(np.clip(y + along * math.sin(heading), 0.0, site_m)),
                )
            )
        x = float(np.clip(x + length * math.cos(heading), 0.0, site_m))
        y = float(np.clip(y + length * math.sin(heading), 0.0, site_m))
        room = f"r{place_id // 10}"
        places.append(Place(place_id, room, x, y, 0.0, leg=Leg(place_id - 1, tuple(trail))))
    return places


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--places", type=int, default=1000)
    parser.add_argument("--site-m", type=float, default=60.0)
    args = parser.parse_args()
    places = recorded_drive(args.places, args.site_m)
    start = time.perf_counter()
    graph = leg_graph(places)
    built_s = time.perf_counter() - start
    starts = places[:: max(1, len(places) // 10)]
    start = time.perf_counter()
    found = [route_out(graph, places, p.id, {p.room}, ROUTE_MAX_M) for p in starts]
    query_ms = (time.perf_counter() - start) / len(starts) * 1000
    waypoints = [len(route.waypoints_xy_m) for route in found if route is not None]
    print(
        f"{len(places)} places, {graph.number_of_nodes()} nodes, {graph.number_of_edges()} edges: "
        f"graph built in {built_s:.1f} s; route_out {query_ms:.0f} ms per query "
        f"({len(waypoints)} of {len(starts)} found, median {np.median(waypoints):.0f} waypoints)"
    )


if __name__ == "__main__":
    main()
