"""``toploc map record``: record panoramas of the robot's camera into the running service's map,
over the bus.

It asks the robot node for a capture (``camera/capture``) and sends it to the map node
(``map/add``) with the room and a pose: by default the robot's odometry (``base/odom``: x, y in
the *odometry* frame, which starts wherever the base was switched on; not the room's frame), or
``--x-m/--y-m/--heading-deg``, or none (``--no-pose``). ``--every-m D`` keeps recording, one
panorama each time the odometry position is D metres (straight line) from the last recording,
while someone drives the robot (the odometry is asked for every 0.2 s), until Ctrl-C (or
``--count``). With odometry poses each recording after the first is stored with its leg (the
place before and the odometry positions driven between, :class:`mapdb.records.Leg`);
``--after ID`` joins the first to place ID (recorded before on the same drive: the base not
switched off since). Recorded routes let the active localizer tell apart look-alike rooms.
``--connect-room`` adds a room-graph edge (``map/connect``) after the first
recording. The running localizer uses the new places a moment later (the map node's reply says
when), without a restart.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from localizer.robot_protocol import Pose2D
from mapdb.records import Leg, check_name
from toploc import bus
from toploc.commands.bus_client import client_session
from toploc.commands.options import robot_id_option, service_endpoint_option, zenoh_config_option

if TYPE_CHECKING:
    from toploc.nodes.mapdb import MapClient
    from toploc.nodes.robot import RemoteRobot

Pose = tuple[float | None, float | None, float | None]
POLL_S = 0.2
"""How often ``--every-m`` asks for the odometry (``base/odom``)."""


def _checked_name(option: str, name: str | None) -> str | None:
    if name is None:
        return None
    try:
        return check_name(name.strip())
    except ValueError as error:
        raise click.BadParameter(str(error), param_hint=option) from None


TRAIL_STEP_M = 0.1
"""``--every-m`` keeps an odometry position in a place's leg every this many metres driven."""


class Recorder:
    """Capture with ``robot`` and add to the map with ``client`` (both over one session).

    With odometry poses, each recording after the first (or after place ``after``) is stored
    with its leg: the place recorded before and the odometry positions :meth:`saw` between
    (:class:`mapdb.records.Leg`), so the active localizer can drive the route again."""

    def __init__(
        self,
        robot: RemoteRobot,
        client: MapClient,
        room: str,
        pose: str,
        fixed: Pose,
        after: int | None = None,
    ) -> None:
        self.robot, self.client, self.room = robot, client, room
        self.pose, self.fixed = pose, fixed
        self.count = 0
        self.previous = after
        self.trail: list[tuple[float, float]] = []

    def saw(self, odometry: Pose2D) -> None:
        """Keep ``odometry``'s position for the next place's leg if it is
        :data:`TRAIL_STEP_M` from the last one kept."""
        point = (odometry.x_m, odometry.y_m)
        if not self.trail or math.dist(point, self.trail[-1]) >= TRAIL_STEP_M:
            self.trail.append(point)

    def odometry(self) -> Pose2D:
        """The robot's odometry now: a ``base/odom`` query (a base driven by hand may publish
        none while it moves)."""
        from toploc.bus.messages import odometry_from_fields
        from toploc.bus.schemas import ODOM

        key_expr = bus.key(self.robot.robot_id, bus.BASE_ODOM)
        session, timeout_s = self.robot.session, self.robot.timeout_s
        message = bus.request_json(session, key_expr, ODOM.fields, None, timeout_s)
        return odometry_from_fields(message)

    def record(self) -> tuple[float, float]:
        """Capture, add, print one line; the odometry position ``(x_m, y_m)`` it was taken at."""
        from toploc.bus.png_codec import encode_png

        odometry = self.odometry()  # position and heading of one instant, just before capture
        capture = self.robot.capture()
        stored: Pose = (None, None, None)
        leg = None
        if self.pose == "odometry":
            stored = (odometry.x_m, odometry.y_m, math.degrees(odometry.heading_rad))
            if self.previous is not None:
                leg = Leg(self.previous, tuple(self.trail[1:]))  # [0]: where the last one was
        elif self.pose == "given":
            stored = self.fixed
        reply = self.client.add(encode_png(capture.image), self.room, *stored, leg=leg)
        self.count += 1
        self.previous, self.trail = reply["place_id"], [(odometry.x_m, odometry.y_m)]
        click.echo(describe_added(self.count, reply, self.pose, stored, leg))
        return odometry.x_m, odometry.y_m


def describe_added(
    n: int, reply: dict[str, Any], pose: str, xyh: Pose, leg: Leg | None = None
) -> str:
    """One line for a recorded panorama."""
    x_m, y_m, heading = xyh
    parts = [] if x_m is None or y_m is None else [f"({x_m:.2f}, {y_m:.2f}) m"]
    parts += [] if heading is None else [f"{heading:.0f}°"]
    parts += [] if leg is None else [f"driven from place {leg.from_place}"]
    frame = "odometry " if pose == "odometry" else ""
    where = frame + ", ".join(parts) if parts else "no pose"
    counts = ", ".join(f"{d} {k}" for d, k in sorted(reply["fingerprints"].items()))
    state = "added as" if reply["new"] else "already in the map as"
    refresh = reply.get("refresh_after_s")
    used = f"; the localizer uses it in {refresh:g} s" if reply["new"] and refresh else ""
    return f"[{n}] {state} place {reply['place_id']} of {reply['room']} ({where}; {counts}){used}"


def follow(
    recorder: Recorder,
    every_m: float,
    count: int | None,
    after_first: Callable[[], None] = lambda: None,
) -> None:
    """Record now (then call ``after_first``), then whenever the odometry is ``every_m`` from
    the last recording; until Ctrl-C or ``count`` recordings. An error after the first is
    printed and retried at the next odometry step."""
    last = recorder.record()
    after_first()
    click.echo(
        f"recording {recorder.room} every {every_m:g} m of odometry: drive the robot; Ctrl-C stops"
    )
    while count is None or recorder.count < count:
        time.sleep(POLL_S)
        try:
            odometry = recorder.odometry()
            recorder.saw(odometry)
            if math.hypot(odometry.x_m - last[0], odometry.y_m - last[1]) >= every_m:
                last = recorder.record()
        except (bus.BusTimeout, bus.BusReplyError, bus.BusMessageError) as error:
            click.echo(f"Error: {error} (retrying at the next step)", err=True)


@click.command("record")
@click.option("--room", required=True, help="The room the robot is in.")
@click.option(
    "--connect-room",
    default=None,
    help="Also add the room-graph edge between --room and this room (it must exist).",
)
@click.option("--x-m", type=float, default=None, help="x in the room's frame, metres.")
@click.option("--y-m", type=float, default=None, help="y in the room's frame, metres.")
@click.option("--heading-deg", type=float, default=None, help="Heading in the room, degrees.")
@click.option("--no-pose", is_flag=True, help="Store no pose (default: the robot's odometry pose).")
@click.option(
    "--after",
    "after",
    type=click.IntRange(min=1),
    default=None,
    metavar="PLACE_ID",
    help="The robot drove here from this place, its odometry not restarted since: store the "
    "leg between them (the active localizer can drive it back).",
)
@click.option(
    "--every-m",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="Keep recording: one panorama every D metres of odometry, until Ctrl-C.",
)
@click.option(
    "--count",
    type=click.IntRange(min=1),
    default=None,
    help="With --every-m: stop after this many panoramas.",
)
@robot_id_option
@service_endpoint_option
@zenoh_config_option
@click.option(
    "--timeout",
    "timeout_s",
    type=click.FloatRange(min=0, min_open=True),
    default=bus.DEFAULT_TIMEOUT_S,
    show_default=True,
    help="Seconds to wait for a capture or the odometry (adding waits up to 60 s).",
)
def record_command(
    room: str,
    connect_room: str | None,
    x_m: float | None,
    y_m: float | None,
    heading_deg: float | None,
    no_pose: bool,
    after: int | None,
    every_m: float | None,
    count: int | None,
    robot_id: str,
    endpoints: tuple[str, ...],
    zenoh_file: Path | None,
    timeout_s: float,
) -> None:
    """Record the robot's panorama into the map of the running service, as a place of --room.

    The pose stored is the robot's odometry (its own frame, not the room's) unless --x-m/--y-m
    (and --heading-deg) or --no-pose are given. Prints the place id.
    """
    from toploc.nodes.mapdb import ADD_TIMEOUT_S, MapClient
    from toploc.nodes.robot import RemoteRobot

    room = _checked_name("--room", room) or room
    connect_room = _checked_name("--connect-room", connect_room)
    given = (x_m, y_m, heading_deg)
    if (x_m is None) != (y_m is None):
        raise click.UsageError("give both --x-m and --y-m, or neither")
    for hint, value in zip(("--x-m", "--y-m", "--heading-deg"), given, strict=True):
        if value is not None and not math.isfinite(value):
            raise click.BadParameter(f"must be a finite number, got {value}", param_hint=hint)
    if every_m is not None and x_m is not None:
        raise click.UsageError("--every-m records where the robot drives: drop --x-m/--y-m")
    if count is not None and every_m is None:
        raise click.UsageError("--count goes with --every-m")
    pose = "none" if no_pose else "given" if any(v is not None for v in given) else "odometry"
    if after is not None and pose != "odometry":
        raise click.UsageError("--after joins odometry poses: drop --x-m/--y-m and --no-pose")
    try:
        with client_session(robot_id, zenoh_file, endpoints) as session:
            robot = RemoteRobot(session, robot_id, timeout_s)
            try:
                client = MapClient(session, robot_id, timeout_s, max(timeout_s, ADD_TIMEOUT_S))
                recorder = Recorder(robot, client, room, pose, given, after)

                def connect() -> None:
                    if connect_room is not None:
                        reply = client.connect(room, connect_room)
                        state = "connected" if reply["added"] else "already connected:"
                        click.echo(f"{state} {room} <-> {connect_room}")

                if every_m is None:
                    recorder.record()
                    connect()
                else:
                    try:
                        follow(recorder, every_m, count, after_first=connect)
                    except KeyboardInterrupt:
                        click.echo("stopped")
                    click.echo(f"recorded {recorder.count} panorama(s) of {room}")
            finally:
                robot.close()
    except bus.BusError as error:
        raise click.ClickException(str(error)) from error
