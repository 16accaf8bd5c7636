"""``toploc drive``: move the base of a running toploc service over the bus (``base/cmd``), or
stop it (``base/stop``), from the command line: e.g. to step between the places of a room while
recording it (``toploc map record``), with no Python to write.

``--turn-deg D --forward-m M`` turns D degrees (counter-clockwise positive) and then drives M
metres (negative: backwards), as one ``base/cmd``; the command waits until the base has done it
and prints what it did: ``turned 90.0 deg, moved 0.50 m, no bump; odometry x 1.20 m, y 0.50 m,
heading 90.0 deg``. ``--stop`` stops the base at once (also during another client's move).

Exit status 1 with ``Error: ...`` (one line) when the base refuses the move (beyond the
service's limits, ``--limits``), stops it (its move timeout), bumps into something (after the
line of what it did), or no service answers within ``--timeout``; a drive that gives up waiting
sends ``base/stop`` first, so the base is not left moving.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import click

from localizer.robot_protocol import MoveResult, Pose2D
from toploc import bus
from toploc.commands.bus_client import client_options, client_session
from toploc.limits import Limits

if TYPE_CHECKING:  # the command imports it when run: cv2 loads with it
    from toploc.nodes.robot import RemoteRobot

DRIVE_TIMEOUT_S = Limits().move_timeout_s + bus.DEFAULT_TIMEOUT_S
STOP_TIMEOUT_S = 2.0
"""How long a drive that gave up waits for its ``base/stop``."""


def describe_move(result: MoveResult, odometry: Pose2D) -> str:
    """One line of what the base did and where its odometry says it is now (degrees, metres)."""
    bump = "bumped" if result.bumped else "no bump"
    return (
        f"turned {math.degrees(result.turned_rad):.1f} deg, moved {result.moved_m:.2f} m, "
        f"{bump}; odometry x {odometry.x_m:.2f} m, y {odometry.y_m:.2f} m, heading "
        f"{math.degrees(odometry.heading_rad):.1f} deg"
    )


def _check_finite(_ctx: click.Context, param: click.Parameter, value: float | None) -> float | None:
    if value is not None and not math.isfinite(value):
        raise click.BadParameter(f"must be a finite number, got {value!r}")
    return value


@click.command("drive")
@client_options
@click.option(
    "--turn-deg",
    type=float,
    default=None,
    callback=_check_finite,
    help="Turn this many degrees first (counter-clockwise positive).",
)
@click.option(
    "--forward-m",
    type=float,
    default=None,
    callback=_check_finite,
    help="Then drive this many metres (negative: backwards).",
)
@click.option("--stop", is_flag=True, help="Stop the base now (nothing else).")
@click.option(
    "--timeout",
    "timeout_s",
    type=click.FloatRange(min=0, min_open=True),
    default=DRIVE_TIMEOUT_S,
    show_default=True,
    help="Seconds to wait for the move to be done (the service stops a move after its "
    "move_timeout_s, 60 s by default); --stop waits this long too.",
)
def drive(
    robot_id: str,
    endpoints: tuple[str, ...],
    zenoh_file: Path | None,
    turn_deg: float | None,
    forward_m: float | None,
    stop: bool,
    timeout_s: float,
) -> None:
    """Drive the base of a running toploc service: turn, then go forward; or --stop.

    One move (base/cmd): turn --turn-deg degrees (counter-clockwise positive), then drive
    --forward-m metres (negative: backwards); it waits until the base has done it and prints
    what the base did and its odometry. Exit status 1 with a one-line error when the base
    bumps into something (after that line), refuses the move (beyond the service's --limits),
    or the service stops it (its move timeout), or no service answers (a drive that gives up
    waiting sends base/stop first).
    """
    from toploc.nodes.robot import RemoteRobot

    if stop and (turn_deg is not None or forward_m is not None):
        raise click.UsageError("--stop stops the base: give it without --turn-deg/--forward-m")
    if not stop and turn_deg is None and forward_m is None:
        raise click.UsageError("give --turn-deg and/or --forward-m (or --stop)")
    try:
        with client_session(robot_id, zenoh_file, endpoints) as session:
            base = RemoteRobot(
                session, robot_id, timeout_s=timeout_s if stop else STOP_TIMEOUT_S,
                move_timeout_s=timeout_s,
            )  # fmt: skip
            with base:
                if stop:
                    base.stop()
                    click.echo("stopped")
                    return
                result = _move(base, math.radians(turn_deg or 0.0), forward_m or 0.0)
                click.echo(describe_move(result, base.odometry()))
    except bus.BusError as error:
        raise click.ClickException(str(error)) from error
    if result.bumped:
        raise click.ClickException(
            f"the base bumped into something: moved {result.moved_m:.2f} m of "
            f"{forward_m or 0.0:.2f} m"
        )


def _move(base: RemoteRobot, turn_rad: float, forward_m: float) -> MoveResult:
    """``base.move``; if no reply comes in time, ``base/stop`` (best effort) before the error."""
    try:
        return base.move(turn_rad, forward_m)
    except bus.BusTimeout as error:
        try:
            base.stop()
        except bus.BusError:
            raise error from None
        raise bus.BusTimeout(f"{error}; sent base/stop") from None
