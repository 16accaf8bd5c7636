"""The ROS 2 options of ``toploc node ros2`` and ``toploc serve --ros2``: which ROS graph the
bridge (:mod:`toploc.nodes.ros2`) joins, and through which Zenoh router."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import click

from toploc.bus import BusConfig
from toploc.bus.config import (
    ROS2_LISTEN_ENDPOINT,
    ROS2_ROUTER_ENDPOINT,
    endpoint_host,
    is_loopback,
    ros2_bus_config,
)
from toploc.bus.ros2.keys import MAX_DOMAIN_ID
from toploc.commands.options import warn_if_exposed
from toploc.nodes.ros2 import NODE_NAME, Ros2Settings

_OPTIONS = (
    click.option(
        "--ros-domain-id",
        type=click.IntRange(0, MAX_DOMAIN_ID),
        default=0,
        show_default=True,
        envvar="ROS_DOMAIN_ID",
        help="The ROS domain of the graph to join. [env: ROS_DOMAIN_ID]",
    ),
    click.option(
        "--ros-namespace",
        default="/",
        show_default=True,
        help=f"The namespace of the ROS node {NODE_NAME!r}: its topics and services are "
        f"/<namespace>/{NODE_NAME}/... (diagnostics: /<namespace>/diagnostics).",
    ),
    click.option(
        "--ros-connect",
        multiple=True,
        help="Zenoh endpoint of the robot's ROS router, rmw_zenohd (repeatable; default: the "
        f"--ros-zenoh-config file's, else {ROS2_ROUTER_ENDPOINT}).",
    ),
    click.option(
        "--ros-listen",
        multiple=True,
        help="Zenoh endpoint the ROS session listens on for ROS nodes to reach it peer to peer "
        f"(repeatable; default: the --ros-zenoh-config file's, else {ROS2_LISTEN_ENDPOINT}, "
        "a port the OS picks).",
    ),
    click.option(
        "--ros-zenoh-config",
        "ros_zenoh_file",
        type=click.Path(dir_okay=False, exists=True, path_type=Path),
        envvar="ZENOH_SESSION_CONFIG_URI",
        default=None,
        help="A Zenoh configuration file (JSON5) for the ROS session, as rmw_zenoh's own "
        "sessions read it; --ros-connect/--ros-listen win over it. [env: "
        "ZENOH_SESSION_CONFIG_URI]",
    ),
)


def ros2_options(command: Any) -> Any:
    """``--ros-domain-id``, ``--ros-namespace``, ``--ros-connect``, ``--ros-listen`` and
    ``--ros-zenoh-config`` (see :func:`ros2_setup`)."""
    for option in reversed(_OPTIONS):
        command = option(command)
    return command


def ros2_setup(
    robot_id: str,
    domain_id: int,
    namespace: str,
    connect: Sequence[str],
    listen: Sequence[str],
    zenoh_file: Path | None,
) -> tuple[BusConfig, Ros2Settings]:
    """The ROS session's configuration and the bridge's settings of :func:`ros2_options`'
    values; a bad value is a one-line error."""
    try:
        settings = Ros2Settings(domain_id, namespace)
    except ValueError as error:
        raise click.BadParameter(str(error), param_hint="--ros-namespace") from None
    try:
        config = ros2_bus_config(robot_id, zenoh_file, connect or None, listen or None)
    except ValueError as error:
        raise click.ClickException(f"ROS session: {error}") from None
    warn_if_exposed(config)  # a ROS client may call localize_active, which drives the robot
    return config, settings


def _port(endpoint: str) -> str | None:
    host = endpoint_host(endpoint)
    return None if host is None else endpoint.rsplit(":", 1)[1].split("?")[0].split("#")[0]


def check_ports_apart(toploc: BusConfig, ros: BusConfig) -> None:
    """Refuse a toploc bus that listens on this machine's port of the ROS router (both
    ``tcp/127.0.0.1:7447`` by default: the second to start fails), naming both options."""
    for listen in toploc.listen:
        for router in ros.connect:
            if is_loopback(listen) and is_loopback(router) and _port(listen) == _port(router):
                raise click.UsageError(
                    f"--listen {listen} is the port of the ROS router (--ros-connect {router}): "
                    "leave --listen out (toploc's bus then goes through the router) or give it "
                    "another port, e.g. --listen tcp/127.0.0.1:7448 "
                    "(and --connect it in toploc's clients)"
                )


def describe_ros2(ros: BusConfig, settings: Ros2Settings) -> str:
    """The line a bridge prints: the node, its domain and the router it joins."""
    namespace = settings.namespace.rstrip("/")
    return (
        f"ROS 2 node {namespace}/{NODE_NAME} in domain {settings.domain_id} via "
        f"{list(ros.connect)} (listen {list(ros.listen)}): topics {namespace}/{NODE_NAME}/"
        f"belief_json, belief, pose, {namespace}/diagnostics; services {namespace}/{NODE_NAME}/"
        "localize, localize_active, reinitialize_global_localization"
    )
