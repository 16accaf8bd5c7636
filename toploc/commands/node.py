"""``toploc node robot|camera|localizer|map|ros2``: one node per process, so that the robot's driver
runs on the robot and the localizer elsewhere if wanted (``toploc serve`` runs them all in one).

Each command opens its own Zenoh session, enters its node with the ``enter_*`` function of
:mod:`toploc.service` that ``serve`` uses too, prints the robot id and what runs, and runs until
Ctrl-C (exit status 130) or SIGTERM (0). Each node refuses to start when its role already runs
for the robot id (``alive/<role>``). The localizer node reloads its map on the map node's
``map/changed``; both read the same SQLite file, so they need the same file (one machine, or
shared storage). ``node map --map-id`` serves the map to a site's robots, which keep replicas of
their own (``toploc serve --map-from``, or ``node localizer --map-from`` beside the robot's own
``node robot``; docs/site.md).
"""

from __future__ import annotations

from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path

import click
import zenoh

from localizer.cameras import parse_camera
from localizer.localizer import LocalizerConfig
from mapdb.errors import MapDatabaseError
from robot.camera_sources import CameraError
from robot.p2os_base import P2osError
from toploc.bus import BusConfig, BusError, open_session
from toploc.bus.config import client_bus_config
from toploc.commands.bus_client import client_options
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
from toploc.commands.ros2_options import describe_ros2, ros2_options, ros2_setup
from toploc.limits import Limits
from toploc.maps import ensure_world_map
from toploc.nodes.sim_truth import subscribe_true_pose
from toploc.robots import ROBOT_SPECS, open_served_robot
from toploc.service import (
    MapRefresher,
    enter_camera_node,
    enter_localizer_nodes,
    enter_map_node,
    enter_robot_node,
    enter_ros2_bridge,
    enter_site_calibration,
)

Enter = Callable[[ExitStack, zenoh.Session, Limits], str]
"""Enters a node (or two) on a session; returns what runs, for the line printed."""
_ERRORS = (BusError, MapDatabaseError, P2osError, CameraError)

SHARED_MAP = "The map (SQLite). The map node and the localizer node need the same file."


@click.group("node")
def node_group() -> None:
    """Run one node of the service per process (toploc serve runs them all in one)."""


def _run(
    config: BusConfig, limits: Limits, describe: str, enter: Enter, stack: ExitStack
) -> StopSignal:
    """Open the session, ``enter(stack, session, limits)`` the node(s), print what runs and
    wait for SIGINT or SIGTERM (returned); a bus, map, base or camera error is one line."""
    stop = stack.enter_context(stop_on_signals())  # left last: the nodes close first
    try:
        session = stack.enter_context(open_session(config))
        what = enter(stack, session, limits)
        click.echo(f"{describe}{what} as {describe_bus(config)}. Ctrl-C stops.")
        stop.wait_for_signal()
    except _ERRORS as error:
        raise click.ClickException(str(error)) from error
    return stop


@node_group.command("robot")
@config_file_option
@long_running
@click.option(
    "--robot",
    "robot_spec",
    default="sim",
    show_default=True,
    callback=check_robot_spec,
    help=f"{ROBOT_SPECS}: the base this node drives (as toploc serve --robot).",
)
@click.option(
    "--source",
    default="sim",
    show_default=True,
    help="Where camera/capture takes panoramas (as toploc serve --source).",
)
@click.option(
    "--no-camera",
    is_flag=True,
    help="Serve the base only: a toploc node camera serves camera/capture for this robot id.",
)
@sim_world_option
@sim_room_option
@sim_seed_option
@db_option(
    "A map whose panorama size the sim camera renders (default: the --sim-world's built-in "
    "map from the cache, as serve; an empty map: 1024 x 192).",
    required=False,
    exists=True,
)
@node_options
def robot_node(
    robot_spec: str,
    source: str,
    no_camera: bool,
    sim_world: str,
    sim_room: str,
    seed: int,
    db_path: Path | None,
    robot_id: str,
    listen: tuple[str, ...],
    connect: tuple[str, ...],
    mode: str | None,
    zenoh_file: Path | None,
    limits_path: Path | None,
) -> None:
    """The robot node: the base (base/*) and its camera (camera/*) until interrupted."""
    config, limits = node_setup(robot_id, listen, connect, mode, zenoh_file, limits_path, False)
    with ExitStack() as stack:
        camera = None if no_camera else open_capture_source(stack, source)
        db = db_path or ensure_world_map(sim_world)
        try:
            robot, where, true_pose = stack.enter_context(
                open_served_robot(robot_spec, source, sim_world, sim_room, seed, db, robot_id)
            )
        except _ERRORS as error:
            raise click.ClickException(str(error)) from error
        assert robot is not None  # a spec always opens a robot

        def enter(stack: ExitStack, session: zenoh.Session, limits: Limits) -> str:
            enter_robot_node(stack, session, robot_id, robot, limits, camera, not no_camera)
            text = where
            if true_pose is not None:
                stack.callback(subscribe_true_pose(session, true_pose).undeclare)
                text += f", its camera at the true pose on toploc/{robot_id}/sim/true_pose"
            return f"{text}; camera: {'none (--no-camera)' if no_camera else source}"

        stop = _run(config, limits, "robot node: ", enter, stack)
    stopped(stop)


@node_group.command("camera")
@config_file_option
@long_running
@click.option(
    "--source",
    required=True,
    help="Where camera/capture takes panoramas: uvc:..., files:DIR, ptu:DIR, omni:... (see "
    "docs/cameras.md; sim needs a robot: toploc node robot).",
)
@node_options
def camera_node(
    source: str,
    robot_id: str,
    listen: tuple[str, ...],
    connect: tuple[str, ...],
    mode: str | None,
    zenoh_file: Path | None,
    limits_path: Path | None,
) -> None:
    """A camera without a base: camera/capture and camera/panorama until interrupted."""
    config, limits = node_setup(robot_id, listen, connect, mode, zenoh_file, limits_path, False)
    with ExitStack() as stack:
        if source == "sim":
            raise click.BadParameter(
                "sim renders the robot's view: run toploc node robot", param_hint="--source"
            )
        camera = open_capture_source(stack, source)
        assert camera is not None

        def enter(stack: ExitStack, session: zenoh.Session, limits: Limits) -> str:
            enter_camera_node(stack, session, robot_id, camera, limits)
            return source

        stop = _run(config, limits, "camera node: ", enter, stack)
    stopped(stop)


@node_group.command("localizer")
@config_file_option
@long_running
@db_option(
    f"{SHARED_MAP} With --map-from: this robot's replica (default "
    "$TOPLOC_HOME/replicas/MAP_ID.db).",
    required=False,
)
@map_from_option(" (the robot's map/* keys are not served: a site robot records through the "
                 "site map's keys, or runs toploc serve --map-from)")  # fmt: skip
@policy_option
@camera_option
@node_options
def localizer_node(
    db_path: Path | None,
    map_from: str | None,
    policy: str,
    camera: str,
    robot_id: str,
    listen: tuple[str, ...],
    connect: tuple[str, ...],
    mode: str | None,
    zenoh_file: Path | None,
    limits_path: Path | None,
) -> None:
    """The localizer and homing nodes, driving the bus's robot node, until interrupted."""
    if map_from is None and db_path is None:
        raise click.UsageError("Missing option '--db' (or --map-from MAP_ID: a site map's replica)")
    if map_from is None and db_path is not None and not db_path.exists():
        raise click.BadParameter(f"map {db_path} does not exist", param_hint="--db")
    config, limits = node_setup(robot_id, listen, connect, mode, zenoh_file, limits_path, False)
    localizer_config = LocalizerConfig(camera=parse_camera(camera))
    map_path = db_path if map_from is None else site_replica(map_from, db_path)
    assert map_path is not None

    def enter(stack: ExitStack, session: zenoh.Session, limits: Limits) -> str:
        refresher.append(enter_localizer_nodes(
            stack, session, robot_id, map_path, policy, localizer_config, limits,
            allow_empty=True, map_from=map_from,
        ).refresher)  # fmt: skip
        if map_from is not None:
            return (f"a replica of site map {map_from} at {map_path} (reloaded as it takes the "
                    "map's changes), driving the bus's robot node")  # fmt: skip
        return f"{map_path} (reloaded on map/changed), driving the bus's robot node"

    refresher: list[MapRefresher] = []
    with ExitStack() as stack:
        stop = _run(config, limits, "localizer and homing nodes: ", enter, stack)
    stopped(stop, refresher[0] if refresher else None)


@node_group.command("map")
@config_file_option
@long_running
@db_option(SHARED_MAP)
@click.option("--new-map", is_flag=True, help="Create the --db file empty if it does not exist.")
@click.option(
    "--map-id",
    "map_id",
    metavar="MAP_ID",
    default=None,
    callback=check_map_id_option,
    help="Serve the map as site map MAP_ID for every robot on the bus (keys toploc/map/MAP_ID/; "
    "robots run toploc serve --map-from MAP_ID with replicas of their own; docs/site.md). A "
    "map not yet served under a name takes this one.",
)
@click.option(
    "--calibrate/--no-calibrate",
    default=True,
    show_default=True,
    help="With --map-id: fit the likelihood again after the robots' writes settle (as serve "
    "does; about 20 s per detector on 100 places), which reaches every replica.",
)
@camera_option
@node_options
def map_node(
    db_path: Path,
    new_map: bool,
    map_id: str | None,
    calibrate: bool,
    camera: str,
    robot_id: str,
    listen: tuple[str, ...],
    connect: tuple[str, ...],
    mode: str | None,
    zenoh_file: Path | None,
    limits_path: Path | None,
) -> None:
    """The map node (map/*; publishes map/changed after each write) until interrupted."""
    config, limits = node_setup(robot_id, listen, connect, mode, zenoh_file, limits_path, False)
    localizer_config = LocalizerConfig(camera=parse_camera(camera))

    def enter(stack: ExitStack, session: zenoh.Session, limits: Limits) -> str:
        enter_map_node(stack, session, robot_id, db_path, limits, localizer_config)
        if map_id is None:
            return str(db_path)
        enter_map_node(stack, session, robot_id, db_path, limits, localizer_config,
                       map_id=map_id)  # fmt: skip
        if calibrate:
            enter_site_calibration(stack, session, map_id, db_path, localizer_config.detector)
        return f"{db_path} as site map {map_id} (toploc/map/{map_id}/**)"

    with map_file(db_path, new_map), ExitStack() as stack:
        stop = _run(config, limits, "map node: ", enter, stack)
    stopped(stop)


@node_group.command("ros2")
@config_file_option
@long_running
@client_options
@ros2_options
def ros2_node(
    robot_id: str,
    endpoints: tuple[str, ...],
    zenoh_file: Path | None,
    ros_domain_id: int,
    ros_namespace: str,
    ros_connect: tuple[str, ...],
    ros_listen: tuple[str, ...],
    ros_zenoh_file: Path | None,
) -> None:
    """The ROS 2 bridge: the service's belief and localize/reset on a ROS 2 graph over
    rmw_zenoh (node toploc; docs/ros2.md), until interrupted. It connects to the service as a
    client (--connect) and to the robot's ROS router (--ros-connect) as a peer."""
    try:
        config = client_bus_config(robot_id, zenoh_file, endpoints or None)
    except ValueError as error:
        raise click.ClickException(str(error)) from None
    ros_config, settings = ros2_setup(
        robot_id, ros_domain_id, ros_namespace, ros_connect, ros_listen, ros_zenoh_file
    )
    click.echo(f"robot id: {robot_id} (keys toploc/{robot_id}/**; --robot-id to change)")

    def enter(stack: ExitStack, session: zenoh.Session, limits: Limits) -> str:
        enter_ros2_bridge(stack, session, robot_id, ros_config, settings)
        return describe_ros2(ros_config, settings)

    with ExitStack() as stack:
        stop = _run(config, Limits(), "ros2 bridge: ", enter, stack)
    stopped(stop)
