"""Load on a site's shared map (issue 22 §3): several robots adding places and localizing at once.

A router session (``tcp/127.0.0.1:<port>``), the site map's node (``MapNode`` with ``map_id``)
on a copy of a small rendered ``building`` map (512 x 96 panoramas every 1.5 m, made once in
``--cache``, default ``$TOPLOC_HOME/bench-site``) and ``--robots`` robot services
(``start_service(map_from=...)``, the simulated robot, each on a replica of its own) all run in
this process, every session a Zenoh client of the router. Each robot has a thread that, for
``--seconds``, adds a panorama through its own ``map/add`` (forwarded to the site map; the
panoramas are rendered beforehand at free poses of the building) and localizes (passive
``localizer/localize``), one after the other. Reported: answered adds/s and localizations/s over
the wall time (and their median latency); the replication lag: for each map version the site
published on ``changed``, the time until each robot's replica held it (median, p95, max over
robots and versions), and the time until each robot's localizer used the place (the service
swaps the grown map in ``--settle`` s after the last change).

Everything shares this process's interpreter and the machine's cores, so the figures are those
of one loaded computer, not of a site's several.

    python benchmarks/bench_site_load.py [--robots 3] [--seconds 20] [--settle 0.5]
"""

from __future__ import annotations

import argparse
import math
import shutil
import statistics
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path

import numpy as np

from localizer.robot_protocol import Pose2D
from mapdb.build import build_map
from mapdb.database import MapDatabase
from mapdb.dataset import read_edges, read_manifest
from mapdb.graph import connect_known_rooms
from mapdb.replica import replica_state
from robot.dataset import render_dataset
from robot.render import PanoramaCamera
from robot.sim_robot import SimulatedRobot
from robot.worlds import make_world
from toploc import bus
from toploc.bus import BusConfig, open_session
from toploc.bus.clients.site_map import SiteMapClient, subscribe_site_changes
from toploc.bus.png_codec import encode_png
from toploc.extraction import resolve_extractor
from toploc.maps import cache_dir, calibrate_map
from toploc.nodes.localizer import LocalizerClient
from toploc.nodes.mapdb import MapClient, MapNode
from toploc.service import start_service

SITE = "bench-site"
CAMERA = PanoramaCamera(512, 96)


def free_endpoint() -> str:
    """A loopback TCP endpoint on a port the kernel says is free now."""
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{sock.getsockname()[1]}"


def site_map(cache: Path) -> Path:
    """The small building map (rendered and built once in ``cache``)."""
    db_path = cache / "map.db"
    if db_path.exists():
        return db_path
    dataset = cache / "dataset"
    render_dataset(dataset, "building", spacing_m=1.5, camera=CAMERA, progress=False)
    building = cache / "building.db"
    with MapDatabase.open(building) as map_db:
        build_map(map_db, read_manifest(dataset), resolve_extractor(("sift",)), workers=0,
                  progress=False)  # fmt: skip
        connect_known_rooms(map_db, read_edges(dataset))
    calibrate_map(building, "sift")
    building.rename(db_path)
    return db_path


def panoramas(n: int, seed: int = 0) -> Iterator[tuple[str, bytes]]:
    """``n`` panoramas (room, PNG) at seeded random free poses of the building."""
    world = make_world("building")
    rng = np.random.default_rng(seed)
    made = 0
    while made < n:
        room = world.rooms[int(rng.integers(len(world.rooms)))]
        x_m, y_m = rng.uniform(0.3, 1.0, 2) * room.size_m
        try:
            pose = world.building_pose(room.name, Pose2D(x_m, y_m, rng.uniform(0, 2 * math.pi)))
            robot = SimulatedRobot(world, pose, camera=CAMERA)
        except ValueError:  # not a free pose
            continue
        made += 1
        yield room.name, encode_png(robot.capture().image)


def client(endpoint: str, robot_id: str) -> BusConfig:
    return BusConfig(robot_id, "client", listen=(), connect=(endpoint,))


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else math.nan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--robots", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--settle", type=float, default=0.5, help="the services' refresh_settle_s")
    parser.add_argument("--cache", type=Path, default=None)
    args = parser.parse_args()
    cache = args.cache or cache_dir() / "bench-site"
    cache.mkdir(parents=True, exist_ok=True)
    start_s = time.monotonic()
    source = site_map(cache)
    print(f"map ready in {time.monotonic() - start_s:.1f} s")
    pool = list(panoramas(args.robots * int(args.seconds * 5 + 20)))
    root = Path(tempfile.mkdtemp(prefix="bench-site-"))
    db_path = root / "site.db"
    shutil.copy(source, db_path)
    endpoint = free_endpoint()
    published: dict[int, float] = {}
    with ExitStack() as stack:
        stack.enter_context(open_session(BusConfig("router", "router", listen=(endpoint,))))
        node_session = stack.enter_context(open_session(client(endpoint, "maphost")))
        stack.enter_context(MapNode(node_session, "maphost", db_path, map_id=SITE))
        watcher = stack.enter_context(open_session(client(endpoint, "watcher")))
        watcher_map = SiteMapClient(watcher, SITE)
        while True:
            try:
                watcher_map.version()
                break
            except bus.BusError:
                time.sleep(0.1)
        stack.callback(subscribe_site_changes(
            watcher, SITE, lambda v: published.setdefault(v, time.monotonic()) if v else None
        ).undeclare)  # fmt: skip
        services = []
        for i in range(args.robots):
            robot_id = f"r{i + 1}"
            world = make_world("building")
            robot = SimulatedRobot(world, world.building_pose("kitchen", Pose2D(2.2, 2.9, 1.0)),
                                   camera=CAMERA, seed=i)  # fmt: skip
            services.append(stack.enter_context(start_service(
                root / f"{robot_id}.db", client(endpoint, robot_id), robot,
                refresh_settle_s=args.settle, recalibrate=False, map_from=SITE,
            )))  # fmt: skip
        print(f"{args.robots} robots on replicas of {SITE}; load for {args.seconds:g} s")
        replica_seen: dict[tuple[int, int], float] = {}
        localizer_seen: dict[tuple[int, int], float] = {}
        added: list[tuple[int, float, float]] = []  # (place id, sent, answered)
        localized: list[float] = []
        stop = threading.Event()
        done = threading.Event()  # every worker has ended

        def watch() -> None:
            while (
                not done.is_set()
                or len(replica_seen) < len(published) * args.robots
                or len(localizer_seen) < len(added) * args.robots
            ):
                now = time.monotonic()
                for i, service in enumerate(services):
                    state = replica_state(root / f"r{i + 1}.db")
                    for v in published:
                        if state is not None and state.version >= v:
                            replica_seen.setdefault((i, v), now)
                    loaded = service.runner.localizer
                    ids = set() if loaded is None else {int(p) for p in loaded.map.table.place_ids}
                    for place_id, _, _ in added:
                        if place_id in ids:
                            localizer_seen.setdefault((i, place_id), now)
                if done.is_set() and now > stop_s + 30:
                    return
                time.sleep(0.02)

        def work(i: int) -> None:
            session_cfg = client(endpoint, f"worker{i}")
            with open_session(session_cfg) as session:
                maps = MapClient(session, f"r{i + 1}")
                localizer = LocalizerClient(session, f"r{i + 1}", localize_timeout_s=60.0)
                images = iter(pool[i :: args.robots])
                while not stop.is_set():
                    room, png = next(images)
                    sent_s = time.monotonic()
                    reply = maps.add(png, room)
                    added.append((int(reply["place_id"]), sent_s, time.monotonic()))
                    sent_s = time.monotonic()
                    localizer.localize()
                    localized.append(time.monotonic() - sent_s)

        watcher_thread = threading.Thread(target=watch, daemon=True)
        workers = [threading.Thread(target=work, args=(i,)) for i in range(args.robots)]
        begin_s = time.monotonic()
        stop_s = math.inf
        watcher_thread.start()
        for worker in workers:
            worker.start()
        time.sleep(args.seconds)
        stop.set()
        stop_s = time.monotonic()
        for worker in workers:
            worker.join(120)
        wall_s = time.monotonic() - begin_s
        done.set()
        watcher_thread.join(60)
        add_latency = [answered - sent for _, sent, answered in added]
        replica_lag = [replica_seen[(i, v)] - t for (i, v) in replica_seen if (t := published[v])]
        by_id = {place_id: answered for place_id, _, answered in added}
        localizer_lag = [t - by_id[p] for (_, p), t in localizer_seen.items()]
        print(f"wall {wall_s:.1f} s, {args.robots} robots adding and localizing at once")
        print(f"adds:          {len(added)} answered, {len(added) / wall_s:.2f}/s, "
              f"median {statistics.median(add_latency) * 1e3:.0f} ms")  # fmt: skip
        print(f"localizations: {len(localized)}, {len(localized) / wall_s:.2f}/s, "
              f"median {statistics.median(localized) * 1e3:.0f} ms")  # fmt: skip
        lag_ms = [percentile(replica_lag, q) * 1e3 for q in (50, 95, 100)]
        missed = len(published) * args.robots - len(replica_lag)
        print(f"replica lag:   {len(replica_lag)} (robot, version) pairs, median {lag_ms[0]:.0f} "
              f"ms, p95 {lag_ms[1]:.0f} ms, max {lag_ms[2]:.0f} ms; {missed} not within "
              "30 s")  # fmt: skip
        print(f"in localizer:  {len(localizer_lag)} (robot, place) pairs, median "
              f"{percentile(localizer_lag, 50):.2f} s, p95 {percentile(localizer_lag, 95):.2f} s "
              f"(settle {args.settle:g} s); {len(added) * args.robots - len(localizer_lag)} not "
              "within 30 s")  # fmt: skip
    shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
