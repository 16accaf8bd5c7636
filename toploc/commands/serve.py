"""``toploc serve``: run the service until Ctrl-C (map, localizer and, by default, the simulated
robot as Zenoh nodes on one session).
"""

from __future__ import annotations

import signal
import threading
from pathlib import Path

import click

from localizer.cameras import parse_camera
from localizer.localizer import LocalizerConfig
from localizer.policy import POLICIES
from mapdb.errors import MapDatabaseError
from robot.worlds import WORLD_NAMES, make_world
from toploc.bus import DEFAULT_ENDPOINT, BusConfig, BusError
from toploc.commands.options import camera_option
from toploc.maps import ensure_world_map, kidnapped_robot
from toploc.service import start_service


@click.command("serve")
@click.option(
    "--db",
    "db_path",
    type=click.Path(dir_okay=False, exists=True, path_type=Path),
    default=None,
    help="The map (default: the --sim-world's map from the cache, made on first use).",
)
@click.option("--robot-id", default="robot", show_default=True)
@click.option("--listen", multiple=True, default=(DEFAULT_ENDPOINT,), show_default=True)
@click.option("--connect", multiple=True, help="Zenoh endpoints to connect to (repeatable).")
@click.option("--mode", type=click.Choice(["peer", "router"]), default="peer", show_default=True)
@click.option("--policy", type=click.Choice(sorted(POLICIES)), default="separating")
@click.option(
    "--sim-world",
    type=click.Choice(WORLD_NAMES),
    default="building",
    show_default=True,
    help="Serve a simulated robot in this rendered world.",
)
@click.option("--sim-room", default="office_b", show_default=True, help="Where it is kidnapped.")
@click.option("--seed", type=int, default=1, show_default=True)
@click.option(
    "--no-sim", is_flag=True, help="No simulated robot: drive the robot node already on the bus."
)
@camera_option
def serve(
    db_path: Path | None,
    robot_id: str,
    listen: tuple[str, ...],
    connect: tuple[str, ...],
    mode: str,
    policy: str,
    sim_world: str,
    sim_room: str,
    seed: int,
    no_sim: bool,
    camera: str,
) -> None:
    """Serve localization for one robot on the Zenoh bus until interrupted."""
    db = db_path or ensure_world_map(sim_world)
    config = BusConfig(robot_id=robot_id, mode=mode, listen=listen, connect=connect)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        robot = None if no_sim else kidnapped_robot(make_world(sim_world), sim_room, seed, db)
        localizer_config = LocalizerConfig(camera=parse_camera(camera))
        with start_service(db, config, robot, policy, localizer_config):
            where = f"{sim_world}/{sim_room}" if robot is not None else "the bus's robot node"
            click.echo(
                f"serving {db} as toploc/{robot_id}/** ({mode}, listen {list(listen)}, "
                f"connect {list(connect)}); robot: {where}. Ctrl-C stops."
            )
            stop.wait()
    except (BusError, MapDatabaseError) as error:  # one line naming the bus or the map
        raise click.ClickException(str(error)) from error
    click.echo("stopped")
