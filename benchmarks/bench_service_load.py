"""Load test of the service over Zenoh: many clients asking ``localizer/belief`` at once.

The service (``toploc.service.start_service``: map, localizer and simulated-robot nodes) runs in
this process on a free loopback port (``tcp/127.0.0.1:<port>``), serving the cached ``building``
map (``toploc.maps.ensure_world_map``, made on first use, about a minute; ``--db`` for another
map) with the simulated robot kidnapped into ``office_b``. For each concurrency level
(``--getters``, default 1, 8, 32) that many client threads, each with its own client session
(``listen=()``, connected to the service's endpoint), call ``LocalizerClient.belief()`` in a loop
for ``--seconds`` (default 60). Per level: the queries answered, queries/s (answered over the
level's wall time), p50/p99 latency of the answered queries, and the queries lost (an error
reply, a timeout after ``--timeout`` s, or a belief with a non-finite number); the RSS of this
process before the level (before the client sessions open) and after it (after they close).

Then the "abuse" level: ``--abuse-getters`` getters again, while one more thread on its own
session sends requests the service must refuse (``base/cmd`` beyond the limits, payloads over
``max_request_bytes``, strings over ``max_string_chars``, negative, non-finite and unknown-room
priors) and resets with huge weights (1e308, accepted by design: the belief must stay finite).
It counts, per kind, the error replies and anything else, checks that the robot never moved
(its odometry before and after), and that every belief it and the getters saw was finite.

Everything runs in one process on this machine: the clients' Python threads share the
interpreter (and its lock) and the cores with the service, so the figures are those of a busy
robot computer, not of the service alone; RSS is that of service and clients together.

    python benchmarks/bench_service_load.py [--getters 1,8,32] [--seconds 60] [--json FILE]
"""

from __future__ import annotations

import argparse
import gc
import json
import logging
import math
import os
import socket
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from process_memory import peak_rss_mib, rss_mib

from robot.worlds import make_world
from toploc import bus
from toploc.bus import BusConfig, BusError, BusReplyError, BusTimeout, open_session
from toploc.limits import Limits
from toploc.maps import ensure_world_map, kidnapped_robot
from toploc.nodes.localizer import LocalizerClient
from toploc.service import start_service

ROBOT_ID = "loadbench"
WORLD, ROOM = "building", "office_b"


def free_endpoint() -> str:
    """A loopback TCP endpoint on a port the kernel says is free now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


def finite_belief(belief: dict[str, Any]) -> bool:
    """Every probability finite and in [0, 1], summing to 1, and a finite entropy."""
    p = np.array(list(belief["rooms"].values()), dtype=float)
    return bool(
        np.all(np.isfinite(p))
        and np.all((p >= 0) & (p <= 1))
        and abs(p.sum() - 1.0) < 1e-6
        and math.isfinite(belief["entropy_bits"])
    )


@dataclass
class Getter:
    """One client thread's record."""

    latencies_ms: list[float] = field(default_factory=list)
    errors: int = 0
    timeouts: int = 0
    non_finite: int = 0
    ended_s: float = 0.0


def get_loop(
    config: BusConfig, timeout_s: float, start: threading.Barrier, stop: threading.Event,
    out: Getter,
) -> None:  # fmt: skip
    """Open a session, wait for the others, then ``belief()`` until ``stop`` is set."""
    with open_session(config) as session:
        client = LocalizerClient(session, ROBOT_ID, timeout_s=timeout_s)
        start.wait()
        while not stop.is_set():
            t0 = time.perf_counter()
            try:
                belief = client.belief()
            except BusTimeout:
                out.timeouts += 1
                continue
            except BusError:
                out.errors += 1
                continue
            out.latencies_ms.append((time.perf_counter() - t0) * 1e3)
            if not finite_belief(belief):
                out.non_finite += 1
        out.ended_s = time.monotonic()


# --- abuse -----------------------------------------------------------------------------------


def abuse_requests(rooms: Sequence[str], limits: Limits) -> list[tuple[str, str, bytes, bool]]:
    """``(name, key suffix, payload, must be refused)`` for each kind of abusive request."""
    too_long = "x" * (limits.max_string_chars + 1)
    n_big = limits.max_request_bytes // 8  # 17 bytes per entry: twice the byte bound
    big_prior = {f"r{i:07d}": 1.0 for i in range(n_big)}
    return [
        ("base/cmd forward_m 10000", bus.BASE_CMD,
         bus.encode("cmd", {"turn_deg": 0.0, "forward_m": 10000.0}), True),
        ("base/cmd turn_deg 1e6", bus.BASE_CMD,
         bus.encode("cmd", {"turn_deg": 1e6, "forward_m": 0.0}), True),
        ("base/cmd forward_m 1e999 (inf)", bus.BASE_CMD,
         b'{"schema": 1, "kind": "cmd", "turn_deg": 0, "forward_m": 1e999}', True),
        (f"base/cmd payload > {limits.max_request_bytes} B", bus.BASE_CMD,
         bus.encode("cmd", {"turn_deg": 0.0, "forward_m": 0.1, "pad": ["y" * 200] * 400}), True),
        (f"reset payload > {limits.max_request_bytes} B", bus.LOCALIZER_RESET,
         bus.encode("reset", {"prior": big_prior}), True),
        (f"reset room name > {limits.max_string_chars} chars", bus.LOCALIZER_RESET,
         bus.encode("reset", {"prior": {too_long: 1.0}}), True),
        ("reset negative weight", bus.LOCALIZER_RESET,
         bus.encode("reset", {"prior": {rooms[0]: -1.0}}), True),
        ("reset weight 1e999 (inf)", bus.LOCALIZER_RESET,
         b'{"schema": 1, "kind": "reset", "prior": {"%s": 1e999}}' % rooms[0].encode(), True),
        ("reset unknown room", bus.LOCALIZER_RESET,
         bus.encode("reset", {"prior": {"no_such_room": 1.0}}), True),
        ("reset huge weights 1e308 (accepted)", bus.LOCALIZER_RESET,
         bus.encode("reset", {"prior": {room: 1e308 for room in rooms}}), False),
    ]  # fmt: skip


@dataclass
class AbuseKind:
    """How the service answered one kind of abusive request."""

    name: str
    must_refuse: bool
    sent: int = 0
    refused: int = 0
    accepted: int = 0
    timeouts: int = 0
    non_finite: int = 0
    example_error: str = ""


def abuse_loop(
    config: BusConfig, timeout_s: float, start: threading.Barrier, stop: threading.Event,
    kinds: list[AbuseKind], requests: list[tuple[str, str, bytes, bool]], pause_s: float,
) -> None:  # fmt: skip
    """Send the abusive requests round-robin, ``pause_s`` apart, until ``stop`` is set."""
    with open_session(config) as session:
        start.wait()
        i = 0
        while not stop.is_set():
            kind, (_, suffix, payload, _) = kinds[i % len(kinds)], requests[i % len(kinds)]
            i += 1
            kind.sent += 1
            key_expr = bus.key(ROBOT_ID, suffix)
            try:
                sample = bus.request(session, key_expr, payload, timeout_s)
            except BusReplyError as error:
                kind.refused += 1
                kind.example_error = kind.example_error or str(error)[:160]
            except BusTimeout:
                kind.timeouts += 1
            else:
                kind.accepted += 1
                if suffix == bus.LOCALIZER_RESET:
                    belief = bus.decode(key_expr, sample.payload.to_bytes())
                    kind.non_finite += not finite_belief(belief)
            stop.wait(pause_s)


# --- one level -------------------------------------------------------------------------------


@dataclass
class Level:
    """The figures of one concurrency level, all measured in this run."""

    name: str
    getters: int
    seconds: float
    queries: int
    per_s: float
    p50_ms: float
    p99_ms: float
    errors: int
    timeouts: int
    non_finite: int
    rss_before_mib: float
    rss_after_mib: float
    peak_rss_mib: float
    load_avg_1min: float
    abuse: list[AbuseKind] = field(default_factory=list)
    robot_moved_m: float = 0.0
    stuck_threads: int = 0

    @property
    def lost(self) -> int:
        return self.errors + self.timeouts + self.non_finite


def run_level(
    name: str, endpoint: str, getters: int, seconds: float, timeout_s: float,
    abuse: Callable[[], tuple[list[AbuseKind], list[tuple[str, str, bytes, bool]]]] | None,
    robot_xy: Callable[[], tuple[float, float]], pause_s: float,
) -> Level:  # fmt: skip
    """Run ``getters`` client threads (and the abuse thread) for ``seconds``."""
    config = BusConfig(robot_id=ROBOT_ID, listen=(), connect=(endpoint,))
    rss_before = rss_mib()
    start, stop = threading.Barrier(getters + (abuse is not None) + 1), threading.Event()
    records = [Getter() for _ in range(getters)]
    threads = [
        threading.Thread(target=get_loop, args=(config, timeout_s, start, stop, r), daemon=True)
        for r in records
    ]
    kinds: list[AbuseKind] = []
    if abuse is not None:
        kinds, requests = abuse()
        threads.append(threading.Thread(
            target=abuse_loop, args=(config, timeout_s, start, stop, kinds, requests, pause_s),
            daemon=True,
        ))  # fmt: skip
    for t in threads:
        t.start()
    start.wait()  # every session is open
    x0, y0 = robot_xy()
    t0 = time.monotonic()
    stop.wait(seconds)
    stop.set()
    for t in threads:
        t.join(2 * timeout_s + 30)
    elapsed = max([r.ended_s for r in records] + [t0 + seconds]) - t0
    x1, y1 = robot_xy()
    counts = [len(r.latencies_ms) for r in records]
    latencies = np.array([ms for r in records for ms in r.latencies_ms])
    p50, p99 = np.percentile(latencies, [50, 99]) if len(latencies) else (math.nan, math.nan)
    errors = sum(r.errors for r in records)
    timeouts = sum(r.timeouts for r in records)
    non_finite = sum(r.non_finite for r in records)
    stuck = sum(t.is_alive() for t in threads)
    del records, latencies, threads  # RSS after: without this level's own records
    gc.collect()
    time.sleep(0.5)  # sessions closed: let their threads and buffers go
    return Level(
        name, getters, elapsed, sum(counts), sum(counts) / elapsed, float(p50), float(p99),
        errors, timeouts, non_finite, rss_before, rss_mib(), peak_rss_mib(),
        os.getloadavg()[0], kinds, math.hypot(x1 - x0, y1 - y0), stuck,
    )  # fmt: skip


# --- output ----------------------------------------------------------------------------------


def print_tables(levels: Sequence[Level], args: argparse.Namespace) -> None:
    print(
        f"\n{args.seconds:g} s per level, client timeout {args.timeout:g} s, map {args.db}; "
        f"service and clients in one process, {os.cpu_count()} cores\n"
    )
    print(
        "| level | getters | queries | queries/s | p50 ms | p99 ms | lost (errors/timeouts/"
        "non-finite) | RSS before MiB | RSS after MiB | peak RSS MiB | load avg 1 min |"
    )
    print("|" + "---|" * 11)
    for v in levels:
        print(
            f"| {v.name} | {v.getters} | {v.queries} | {v.per_s:.0f} | {v.p50_ms:.2f} "
            f"| {v.p99_ms:.2f} | {v.lost} ({v.errors}/{v.timeouts}/{v.non_finite}) "
            f"| {v.rss_before_mib:.0f} | {v.rss_after_mib:.0f} | {v.peak_rss_mib:.0f} "
            f"| {v.load_avg_1min:.1f} |"
        )
    for v in levels:
        if v.stuck_threads:
            print(f"level {v.name}: {v.stuck_threads} client thread(s) had not ended")
    for v in levels:
        if not v.abuse:
            continue
        print(f"\nabuse during level {v.name!r}: robot moved {v.robot_moved_m:.3f} m\n")
        print("| request | expected | sent | error reply | accepted | timeout | non-finite |")
        print("|---|---|---|---|---|---|---|")
        for k in v.abuse:
            expected = "refused" if k.must_refuse else "accepted, finite"
            print(
                f"| {k.name} | {expected} | {k.sent} | {k.refused} | {k.accepted} "
                f"| {k.timeouts} | {k.non_finite} |"
            )
        held = all(
            (k.refused == k.sent) if k.must_refuse else (k.accepted == k.sent and not k.non_finite)
            for k in v.abuse
        )
        verdict = "held" if held and v.robot_moved_m == 0 and not v.non_finite else "NOT held"
        print(f"\nbounds under load: {verdict}")
        for k in v.abuse:
            if k.example_error:
                print(f"  {k.name}: {k.example_error}")


def main(argv: Sequence[str] | None = None) -> list[Level]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--getters", default="1,8,32", help="comma-separated client counts")
    parser.add_argument("--seconds", type=float, default=60.0, help="duration of each level")
    parser.add_argument(
        "--abuse-getters",
        type=int,
        default=None,
        help="getters during the abuse level (default: the largest; 0 skips)",
    )
    parser.add_argument(
        "--abuse-pause", type=float, default=0.02, help="seconds between two abusive requests"
    )
    parser.add_argument(
        "--timeout", type=float, default=bus.DEFAULT_TIMEOUT_S, help="client query timeout, s"
    )
    parser.add_argument("--db", type=Path, default=None, help="map (default: the building map)")
    parser.add_argument("--seed", type=int, default=1, help="seeds the kidnapped robot's pose")
    parser.add_argument("--json", type=Path, default=None, help="also save the results here")
    args = parser.parse_args(argv)  # fmt: skip
    levels = [int(s) for s in args.getters.split(",") if s.strip()]
    abuse_getters = max(levels) if args.abuse_getters is None else args.abuse_getters
    # The refused requests are expected: keep the nodes' warning per error reply off stderr.
    logging.getLogger("toploc").setLevel(logging.ERROR)

    args.db = args.db or ensure_world_map(WORLD)
    robot = kidnapped_robot(make_world(WORLD), ROOM, args.seed, args.db)

    def robot_xy() -> tuple[float, float]:
        odometry = robot.odometry()
        return odometry.x_m, odometry.y_m

    endpoint = free_endpoint()
    limits = Limits()
    results: list[Level] = []
    service = BusConfig(robot_id=ROBOT_ID, listen=(endpoint,))
    with start_service(args.db, service, robot, limits=limits):
        print(f"service on {endpoint}; RSS {rss_mib():.0f} MiB", flush=True)
        rooms: list[str] = []
        with open_session(BusConfig(robot_id=ROBOT_ID, listen=(), connect=(endpoint,))) as s:
            deadline = time.monotonic() + 10
            while not rooms:
                try:
                    rooms = sorted(LocalizerClient(s, ROBOT_ID).belief()["rooms"])
                except BusError:
                    if time.monotonic() > deadline:
                        raise
                    time.sleep(0.1)
        for n in levels:
            print(f"level: {n} getters for {args.seconds:g} s ...", flush=True)
            results.append(
                run_level(
                    str(n),
                    endpoint,
                    n,
                    args.seconds,
                    args.timeout,
                    None,
                    robot_xy,
                    args.abuse_pause,
                )
            )
        if abuse_getters > 0:
            print(f"level: abuse, {abuse_getters} getters for {args.seconds:g} s ...", flush=True)

            def abuse() -> tuple[list[AbuseKind], list[tuple[str, str, bytes, bool]]]:
                requests = abuse_requests(rooms, limits)
                return [AbuseKind(name, must) for name, _, _, must in requests], requests

            results.append(
                run_level(
                    "abuse", endpoint, abuse_getters, args.seconds, args.timeout, abuse, robot_xy,
                    args.abuse_pause,
                )
            )  # fmt: skip
    print_tables(results, args)
    if args.json:
        saved = {
            "settings": {k: str(v) if isinstance(v, Path) else v for k, v in vars(args).items()},
            "cpu_count": os.cpu_count(),
            "levels": [asdict(v) | {"lost": v.lost} for v in results],
        }
        args.json.write_text(json.dumps(saved, indent=2, allow_nan=True))
        print(f"\nsaved {args.json}")
    return results


if __name__ == "__main__":
    main()
