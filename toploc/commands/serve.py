"""``toploc serve``: run the service until Ctrl-C (map, localizer and, by default, the simulated
robot as Zenoh nodes on one session).
"""

from __future__ import annotations

import signal
import threading
from contextlib import ExitStack
from pathlib import Path

import click

from localizer.cameras import parse_camera
from localizer.localizer import LocalizerConfig
from localizer.policy import POLICIES
from localizer.robot_protocol import Camera
from mapdb.database import MapDatabase
from mapdb.errors import MapDatabaseError
from robot.camera_sources import CameraError, open_source
from robot.p2os_base import P2osError
from robot.worlds import WORLD_NAMES
from toploc.bus import DEFAULT_ENDPOINT, BusConfig, BusError
from toploc.bus_config import bus_config
from toploc.commands.options import (
    camera_option,
    robot_id_option,
    warn_if_exposed,
    zenoh_config_option,
)
from toploc.limits import Limits, load_limits
from toploc.maps import ensure_world_map
from toploc.nodes.sim_truth import subscribe_true_pose
from toploc.robots import ROBOT_SPECS, open_robot, parse_robot_spec, true_pose_camera
from toploc.service import start_service


def _check_robot_spec(_ctx: click.Context, _param: click.Parameter, value: str) -> str:
    try:
        parse_robot_spec(value)
    except ValueError as error:
        raise click.BadParameter(str(error)) from None
    return value


@click.command("serve")
@click.option(
    "--db",
    "db_path",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="The map (default: the --sim-world's map from the cache, made on first use); it may "
    "have no places yet (record them with toploc map record).",
)
@click.option(
    "--new-map",
    is_flag=True,
    help="Create the --db file as an empty map if it does not exist.",
)
@robot_id_option
@click.option(
    "--listen",
    multiple=True,
    help=f"Zenoh endpoint to listen on (repeatable; default: the --zenoh-config file's, else "
    f"{DEFAULT_ENDPOINT}).",
)
@click.option(
    "--connect",
    multiple=True,
    help="Zenoh endpoint to connect to (repeatable; default: the --zenoh-config file's).",
)
@click.option(
    "--mode",
    type=click.Choice(["peer", "router"]),
    default=None,
    help="Zenoh mode (default: the --zenoh-config file's, else peer).",
)
@zenoh_config_option
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
@click.option(
    "--robot",
    "robot_spec",
    default="sim",
    show_default=True,
    callback=_check_robot_spec,
    help=f"{ROBOT_SPECS}: the simulated robot, a P2OS simulator in this process driven over "
    "the serial protocol (the sim camera at its true pose), or a Pioneer on serial port PORT.",
)
@click.option(
    "--limits",
    "limits_path",
    type=click.Path(dir_okay=False, exists=True, path_type=Path),
    default=None,
    help="A TOML file of bounds (max_forward_m, max_turn_deg, ...; see the README's Limits).",
)
@camera_option
@click.option(
    "--source",
    default="sim",
    show_default=True,
    help=(
        "Where camera/capture takes panoramas: sim (the simulated robot's renderer), uvc:N or "
        "uvc:VIDEO[,layout=dual-fisheye] (a 360° webcam), files:DIR (the next image of a "
        "folder), ptu:DIR[,step_deg=S,focal_px=F] (a pan sweep stitched), or "
        "omni:CX,CY,R0,R1[:DEVICE|FILE] (a mirror camera, unwrapped). With --robot p2os:PORT, "
        "sim renders at the true pose a toploc sim p2os --bus publishes (simulation only)."
    ),
)
def serve(
    db_path: Path | None,
    new_map: bool,
    robot_id: str,
    listen: tuple[str, ...],
    connect: tuple[str, ...],
    mode: str | None,
    zenoh_file: Path | None,
    policy: str,
    sim_world: str,
    sim_room: str,
    seed: int,
    no_sim: bool,
    robot_spec: str,
    camera: str,
    source: str,
    limits_path: Path | None,
) -> None:
    """Serve localization for one robot on the Zenoh bus until interrupted."""
    try:
        limits = Limits() if limits_path is None else load_limits(limits_path)
    except ValueError as error:
        raise click.ClickException(f"--limits: {error}") from error
    try:
        config = bus_config(robot_id, zenoh_file, mode, listen or None, connect or None)
    except ValueError as error:
        raise click.ClickException(str(error)) from None
    db_path = _map_path(db_path, new_map)
    click.echo(f"robot id: {robot_id} (keys toploc/{robot_id}/**; --robot-id to change)")
    warn_if_exposed(config)
    if no_sim and source != "sim":
        raise click.ClickException(
            f"--source {source}: the camera is served by this service's robot node, which "
            "--no-sim leaves out (a camera without a base is not served yet)"
        )
    with ExitStack() as stack:
        capture_from = None
        if source != "sim":  # opened first: a wrong source fails before a map is made
            try:
                capture_from = open_source(source)
            except CameraError as error:
                raise click.ClickException(f"--source: {error}") from None
            stack.callback(getattr(capture_from, "close", lambda: None))
        _serve(db_path, config, policy, sim_world, sim_room, seed, no_sim, robot_spec, camera,
               limits, source, capture_from)  # fmt: skip
    click.echo("stopped")


def _map_path(db_path: Path | None, new_map: bool) -> Path | None:
    """``--db``, created empty with ``--new-map``; a missing one is an error."""
    if db_path is None:
        if new_map:
            raise click.UsageError("--new-map needs --db FILE")
        return None
    if not db_path.exists():
        if not new_map:
            raise click.BadParameter(
                f"map {db_path} does not exist (--new-map creates it empty)", param_hint="--db"
            )
        try:
            MapDatabase.open(db_path, create=True).close()
        except MapDatabaseError as error:
            raise click.ClickException(str(error)) from error
    return db_path


def _serve(
    db_path: Path | None,
    config: BusConfig,
    policy: str,
    sim_world: str,
    sim_room: str,
    seed: int,
    no_sim: bool,
    robot_spec: str,
    camera: str,
    limits: Limits,
    source: str,
    capture_from: Camera | None,
) -> None:
    """Run the service until SIGINT or SIGTERM."""
    robot_id = config.robot_id
    db = db_path or ensure_world_map(sim_world)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    spec = None if no_sim else robot_spec
    try:
        localizer_config = LocalizerConfig(camera=parse_camera(camera))
        base_camera, true_pose = None, None
        if spec is not None and parse_robot_spec(spec)[0] == "p2os" and source == "sim":
            base_camera, true_pose = true_pose_camera(sim_world, robot_id, db, seed)
        with (
            open_robot(spec, sim_world, sim_room, seed, db, base_camera) as (robot, where),
            start_service(
                db, config, robot, policy, localizer_config, limits, capture_from,
                allow_empty=db_path is not None,
            ) as service,
            ExitStack() as stack,
        ):  # fmt: skip
            if true_pose is not None:
                stack.callback(subscribe_true_pose(service.session, true_pose).undeclare)
                where += f", its camera at the true pose on toploc/{robot_id}/sim/true_pose"
            click.echo(
                f"serving {db} as toploc/{robot_id}/** ({config.mode}, listen "
                f"{list(config.listen)}, connect {list(config.connect)}); robot: {where}; "
                f"camera: {source}. Ctrl-C stops."
            )
            stop.wait()
    except (BusError, MapDatabaseError, P2osError) as error:  # one line naming what failed
        raise click.ClickException(str(error)) from error
