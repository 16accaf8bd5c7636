"""Command-line options that several ``toploc`` commands share."""

from __future__ import annotations

import click

from localizer.cameras import parse_camera


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
