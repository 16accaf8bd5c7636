"""``toploc serve``: run the service until Ctrl-C (map, localizer and, by default, the simulated
robot as Zenoh nodes on one session; ``toploc node ROLE`` runs one node per process).

Exit status: 130 after Ctrl-C (SIGINT), 0 after SIGTERM (a service manager's stop), 1 with
``Error: ...`` when it cannot start; a map that ``--new-map`` created is then deleted again.
Without ``--db`` it serves toploc's built-in world map, which ``map/add`` and ``map/connect``
refuse to write (record your own with ``--db FILE --new-map``). With ``--map-from MAP_ID`` the
robot is one of a site's (docs/site.md): it localizes on its own replica (``--db``, default
``$TOPLOC_HOME/replicas/MAP_ID.db``) of the site map a ``toploc node map --map-id MAP_ID``
serves, and its ``map/add`` goes to that map.
"""

from __future__ import annotations

from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path

import click

from localizer.cameras import parse_camera
from localizer.localizer import LocalizerConfig
from localizer.robot_protocol import Camera
from mapdb.errors import MapDatabaseError
from robot.p2os_base import P2osError
from toploc.bus import BusConfig, BusError, open_session
from toploc.bus.config import ROS2_LISTEN_ENDPOINT
from toploc.commands.config_file import config_file_option
from toploc.commands.options import (
    StopSignal,
    camera_option,
    check_map_id_option,
    check_robot_spec,
    db_option,
    describe_bus,
    long_running,
    map_file,
    map_from_option,
    node_options,
    node_setup,
    open_capture_source,
    policy_option,
    sim_room_option,
    sim_seed_option,
    sim_world_option,
    site_replica,
    stop_on_signals,
    stopped,
)
from toploc.commands.ros2_options import (
    check_ports_apart,
    describe_ros2,
    ros2_options,
    ros2_setup,
)
from toploc.limits import Limits
from toploc.maps import ensure_world_map
from toploc.nodes.ros2 import Ros2Settings
from toploc.nodes.sim_truth import subscribe_true_pose
from toploc.robots import ROBOT_SPECS, open_served_robot
from toploc.service import MapRefresher, enter_replica, enter_ros2_bridge, start_service


@click.command("serve")
@config_file_option
@long_running
@db_option(
    "The map; it may have no places yet (record them with toploc map record). Default: "
    "toploc's built-in map of the --sim-world, from the cache (made on first use), which the "
    "bus does not write to.",
    required=False,
)
@click.option(
    "--new-map",
    is_flag=True,
    help="Create the --db file as an empty map if it does not exist.",
)
@map_from_option("; map/add goes to the site map")
@click.option(
    "--map-id",
    "map_id",
    metavar="MAP_ID",
    default=None,
    callback=check_map_id_option,
    help="Also serve the --db map as site map MAP_ID to other robots (toploc/map/MAP_ID/; they "
    "run serve --map-from MAP_ID): the map host is a robot too. toploc node map --map-id "
    "serves it without a robot.",
)
@node_options
@policy_option
@sim_world_option
@sim_room_option
@sim_seed_option
@click.option(
    "--no-sim", is_flag=True, help="No simulated robot: drive the robot node already on the bus."
)
@click.option(
    "--robot",
    "robot_spec",
    default="sim",
    show_default=True,
    callback=check_robot_spec,
    help=f"{ROBOT_SPECS}: the simulated robot, a P2OS simulator in this process driven over "
    "the serial protocol (the sim camera at its true pose), or a Pioneer on serial port PORT.",
)
@camera_option
@click.option(
    "--ros2",
    is_flag=True,
    help="Also join the robot's ROS 2 graph over rmw_zenoh as node toploc (the belief as "
    "topics, localize/reset as services; docs/ros2.md); the --ros-* options say where.",
)
@ros2_options
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
    map_from: str | None,
    map_id: str | None,
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
    ros2: bool,
    ros_domain_id: int,
    ros_namespace: str,
    ros_connect: tuple[str, ...],
    ros_listen: tuple[str, ...],
    ros_zenoh_file: Path | None,
    source: str,
    limits_path: Path | None,
) -> None:
    """Serve localization for one robot on the Zenoh bus until interrupted.

    Every option may come from a TOML file instead (--config FILE.toml): one key per option,
    its name as above without the leading dashes (robot-id, not robot_id); a flag takes true
    or false, a repeatable option a list of strings; relative paths are relative to the
    file's folder. Options on the command line (and TOPLOC_ZENOH_CONFIG) win over the file.
    An unknown key or a value of the wrong type is an error naming the file and the key.
    For example:

    \b
        robot-id = "kitchen-bot"
        db = "kitchen.db"
        listen = ["tcp/127.0.0.1:7447"]
        policy = "most-likely"
        limits = "limits.toml"
        robot = "p2os:/dev/ttyUSB0"
        source = "uvc:0"
    """
    # a site's robot or map host that connects to the site router listens nowhere, as a node
    site = map_from is not None or map_id is not None
    config, limits = node_setup(robot_id, listen, connect, mode, zenoh_file, limits_path, not site)
    if no_sim and source != "sim":
        raise click.ClickException(
            f"--source {source}: the camera is served by this service's robot node, which "
            "--no-sim leaves out (toploc node camera serves a camera without a base)"
        )
    ros = None
    if ros2:
        ros = ros2_setup(config.robot_id, ros_domain_id, ros_namespace, ros_connect, ros_listen,
                         ros_zenoh_file)  # fmt: skip
        if not (listen or connect or zenoh_file):
            # one Zenoh network: toploc's keys travel through the robot's router, where the
            # clients (tcp/127.0.0.1:7447 by default) find them. A peer of the router that
            # listens on an ephemeral loopback port, as an rmw_zenoh node does: the router
            # tells other peers that address (it does not carry peer-to-peer traffic itself)
            config = replace(config, listen=(ROS2_LISTEN_ENDPOINT,), connect=ros[0].connect)
            click.echo(f"toploc bus: through the ROS router at {', '.join(ros[0].connect)}")
        check_ports_apart(config, ros[0])
    if map_id is not None and (map_from is not None or db_path is None):
        raise click.UsageError("--map-id serves the --db map (not a replica: no --map-from)")
    if map_from is not None:
        if new_map:
            raise click.UsageError("--new-map and --map-from: a replica is made from the site map")
        replica = site_replica(map_from, db_path)
        with ExitStack() as stack:
            capture_from = open_capture_source(stack, source)
            if not replica.exists():
                _first_replica(config, map_from, replica)
            stop, refresher = _serve(replica, config, policy, sim_world, sim_room, seed, no_sim,
                                     robot_spec, camera, limits, source, capture_from, ros,
                                     map_from)  # fmt: skip
        stopped(stop, refresher)
        return
    with map_file(db_path, new_map) as db_path, ExitStack() as stack:
        capture_from = open_capture_source(stack, source)  # first: fails before a map is made
        stop, refresher = _serve(db_path, config, policy, sim_world, sim_room, seed, no_sim,
                                 robot_spec, camera, limits, source, capture_from, ros,
                                 map_id=map_id)  # fmt: skip
    stopped(stop, refresher)


def _first_replica(config: BusConfig, map_id: str, replica: Path) -> None:
    """Make the robot's first replica of site map ``map_id`` (its panorama size is the sim
    camera's); one line if the map node cannot be reached."""
    click.echo(f"making replica {replica} of site map {map_id} ...")
    try:
        with open_session(config) as session, ExitStack() as stack:
            enter_replica(stack, session, map_id, replica)
    except (BusError, MapDatabaseError) as error:
        raise click.ClickException(str(error)) from error


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
    ros: tuple[BusConfig, Ros2Settings] | None = None,
    map_from: str | None = None,
    map_id: str | None = None,
) -> tuple[StopSignal, MapRefresher]:
    """Run the service until SIGINT or SIGTERM; the signal and the service's map refresher
    (``map_from``: ``db_path`` is the robot's replica of that site map; ``map_id``: it is also
    served as that site map)."""
    db = db_path or ensure_world_map(sim_world)
    spec = None if no_sim else robot_spec
    try:
        localizer_config = LocalizerConfig(camera=parse_camera(camera))
        with (
            stop_on_signals() as stop,  # left last: the service and the robot close first
            open_served_robot(spec, source, sim_world, sim_room, seed, db, config.robot_id) as (
                robot, where, true_pose,
            ),
            start_service(
                db, config, robot, policy, localizer_config, limits, capture_from,
                allow_empty=db_path is not None, builtin_map=db_path is None,
                map_from=map_from, map_id=map_id,
            ) as service,
            ExitStack() as stack,
        ):  # fmt: skip
            if true_pose is not None:
                stack.callback(subscribe_true_pose(service.session, true_pose).undeclare)
                where += f", its camera at the true pose on toploc/{config.robot_id}/sim/true_pose"
            if ros is not None:
                enter_ros2_bridge(stack, service.session, config.robot_id, *ros)
                where += f"; {describe_ros2(*ros)}"
            what = f"a replica of site map {map_from} at {db}" if map_from else str(db)
            what += f", also as site map {map_id}" if map_id else ""
            click.echo(
                f"serving {what} as {describe_bus(config)}; robot: {where}; camera: {source}. "
                "Ctrl-C stops."
            )
            stop.wait_for_signal()
        return stop, service.refresher
    except (BusError, MapDatabaseError, P2osError) as error:  # one line naming what failed
        raise click.ClickException(str(error)) from error
