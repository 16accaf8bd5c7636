"""Command-line options that several ``toploc`` commands share."""

from __future__ import annotations

from pathlib import Path

import click

from localizer.cameras import parse_camera
from toploc.bus import DEFAULT_ENDPOINT, BusConfig, check_robot_id, default_robot_id
from toploc.bus_config import exposure_warning


def _check_camera(_ctx: click.Context, _param: click.Parameter, value: str) -> str:
    try:
        return str(parse_camera(value))
    except ValueError as error:
        raise click.BadParameter(str(error)) from None


camera_option = click.option(
    "--camera",
    default="auto",
    show_default=True,
    callback=_check_camera,
    help=(
        "The panoramas' camera model: auto (a 2:1 image is equirectangular, any other a "
        "cylinder), cylinder, equirect, or omni:CX,CY,R0,R1 (a mirror image, unwrapped around "
        "centre CX,CY between radii R0 and R1, pixels)."
    ),
)


def _check_robot_id(_ctx: click.Context, _param: click.Parameter, value: str) -> str:
    try:
        return check_robot_id(value)
    except ValueError as error:
        raise click.BadParameter(str(error)) from None


robot_id_option = click.option(
    "--robot-id",
    default=default_robot_id,
    show_default=f"this machine's host name, {default_robot_id()}",
    callback=_check_robot_id,
    help="The robot id in the keys (toploc/<robot-id>/...).",
)

service_endpoint_option = click.option(
    "--connect",
    "endpoints",
    multiple=True,
    help=f"Zenoh endpoint of the service (repeatable; default: the --zenoh-config file's, else "
    f"{DEFAULT_ENDPOINT}).",
)
"""A client command's ``--connect`` (the ``endpoints`` parameter)."""

zenoh_config_option = click.option(
    "--zenoh-config",
    "zenoh_file",
    type=click.Path(dir_okay=False, path_type=Path),
    envvar="TOPLOC_ZENOH_CONFIG",
    default=None,
    help=(
        "A Zenoh configuration file (JSON5) to start the session from: user/password "
        "authentication, access control, TLS (README, Security). --mode/--listen/--connect "
        "given on the command line win over it; the file's win over toploc's defaults. "
        "[env: TOPLOC_ZENOH_CONFIG]"
    ),
)


def warn_if_exposed(cfg: BusConfig) -> None:
    """Print a warning on stderr if ``cfg`` listens beyond loopback without authentication."""
    warning = exposure_warning(cfg)
    if warning is not None:
        click.echo(f"WARNING: {warning}", err=True)
