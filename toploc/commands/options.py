"""Command-line options that several ``toploc`` commands share."""

from __future__ import annotations

import inspect
import os
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from localizer.cameras import parse_camera
from localizer.policy import POLICIES
from localizer.robot_protocol import Camera
from mapdb.database import MapDatabase
from mapdb.errors import MapDatabaseError
from robot.worlds import WORLD_NAMES
from toploc.bus import (
    DEFAULT_ENDPOINT,
    BusConfig,
    check_map_id,
    check_robot_id,
    default_robot_id,
)
from toploc.bus.config import bus_config, exposure_warning
from toploc.limits import Limits, load_limits
from toploc.maps import cache_dir

if TYPE_CHECKING:
    from toploc.service import MapRefresher


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


policy_option = click.option(
    "--policy",
    type=click.Choice(sorted(POLICIES)),
    default="separating",
    show_default=True,
    help="Where an active localization drives when the belief is ambiguous: separating (the "
    "likely room's place whose view differs most from the rival rooms', minus travel) or "
    "most-likely (the likely room's best-matching place, as the thesis).",
)
sim_world_option = click.option(
    "--sim-world",
    type=click.Choice(WORLD_NAMES),
    default="building",
    show_default=True,
    help="The rendered world of the simulated robot.",
)
sim_room_option = click.option(
    "--sim-room",
    default="office_b",
    show_default=True,
    help="The room of --sim-world the simulated robot is kidnapped into.",
)
sim_seed_option = click.option(
    "--seed",
    type=int,
    default=1,
    show_default=True,
    help="Seeds the simulated robot: its pose in --sim-room, its camera noise and motion.",
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
        "authentication, access control, TLS (docs/security.md). --mode/--listen/--connect "
        "given on the command line win over it; the file's win over toploc's defaults. "
        "[env: TOPLOC_ZENOH_CONFIG]"
    ),
)


def warn_if_exposed(cfg: BusConfig) -> None:
    """Print a warning on stderr if ``cfg`` listens beyond loopback without authentication."""
    warning = exposure_warning(cfg)
    if warning is not None:
        click.echo(f"WARNING: {warning}", err=True)


listen_option = click.option(
    "--listen",
    multiple=True,
    help=f"Zenoh endpoint to listen on (repeatable; default: the --zenoh-config file's, else "
    f"{DEFAULT_ENDPOINT}).",
)
connect_option = click.option(
    "--connect",
    multiple=True,
    help="Zenoh endpoint to connect to (repeatable; default: the --zenoh-config file's).",
)
mode_option = click.option(
    "--mode",
    type=click.Choice(["peer", "router"]),
    default=None,
    help="Zenoh mode (default: the --zenoh-config file's, else peer).",
)
limits_option = click.option(
    "--limits",
    "limits_path",
    type=click.Path(dir_okay=False, exists=True, path_type=Path),
    default=None,
    help="A TOML file of bounds (max_forward_m, max_turn_deg, ...; see docs/limits.md).",
)


def node_options(command: Any) -> Any:
    """The options of a command that runs nodes: ``--robot-id``, ``--listen``, ``--connect``,
    ``--mode``, ``--zenoh-config`` and ``--limits`` (see :func:`node_setup`)."""
    options = (robot_id_option, listen_option, connect_option, mode_option, zenoh_config_option)
    command = limits_option(command)
    for option in reversed(options):
        command = option(command)
    return command


def node_setup(
    robot_id: str,
    listen: tuple[str, ...],
    connect: tuple[str, ...],
    mode: str | None,
    zenoh_file: Path | None,
    limits_path: Path | None,
    listen_when_connecting: bool = True,
) -> tuple[BusConfig, Limits]:
    """The bus configuration and limits of :func:`node_options`' values (one-line errors);
    prints the robot id and warns when the session is exposed. Without
    ``listen_when_connecting`` (``toploc node``), ``--connect`` without ``--listen`` (and no
    ``--zenoh-config``) listens nowhere and is a Zenoh client unless ``--mode`` says: the node
    it connects to routes between its clients (two peers that listen nowhere do not meet)."""
    try:
        limits = Limits() if limits_path is None else load_limits(limits_path)
    except ValueError as error:
        raise click.ClickException(f"--limits: {error}") from error
    try:
        listen_nowhere = connect and not (listen or zenoh_file or listen_when_connecting)
        given_listen = () if listen_nowhere else listen or None
        mode = mode or ("client" if listen_nowhere else None)
        config = bus_config(robot_id, zenoh_file, mode, given_listen, connect or None)
    except ValueError as error:
        raise click.ClickException(str(error)) from None
    click.echo(f"robot id: {robot_id} (keys toploc/{robot_id}/**; --robot-id to change)")
    warn_if_exposed(config)
    return config, limits


EXIT_CTRL_C = 130
"""The exit status of a long-running command stopped by Ctrl-C (SIGINT): 128 + 2, as shells
report it. Stopped by SIGTERM (a service manager's stop) it exits 0, which systemd counts as a
clean stop."""
STOP_SIGNALS_HELP = (
    "Ctrl-C (SIGINT) stops it with exit status 130; SIGTERM (a service manager's stop) with 0."
)
"""The sentence each long-running command's help ends with (:func:`long_running`)."""


def long_running(command: Any) -> Any:
    """Put under ``@click.command``: ends the command's help with :data:`STOP_SIGNALS_HELP`
    (it must wait on :func:`stop_on_signals` and exit through :func:`stopped`)."""
    command.__doc__ = f"{inspect.cleandoc(command.__doc__ or '')}\n\n{STOP_SIGNALS_HELP}"
    return command


class StopSignal(threading.Event):
    """Set by SIGINT or SIGTERM (:func:`stop_on_signals`); ``signum``: the first one."""

    def __init__(self) -> None:
        super().__init__()
        self.signum: int | None = None

    def wait_for_signal(self) -> None:
        """Block the main thread until SIGINT or SIGTERM has set the event.

        Waits in short slices, not at once: the kernel may deliver the signal to any thread
        (Zenoh runs many), and Python runs its handler only when the main thread next executes
        bytecode; a main thread asleep in one untimed wait would never run it (a node once went
        on for 20 s after SIGTERM, its main thread in ``Event.wait()``)."""
        while not self.wait(0.2):
            pass

    def received(self, signum: int) -> None:
        """Record ``signum`` (the first only) and set the event."""
        if self.signum is None:
            self.signum = signum
        self.set()

    @property
    def exit_code(self) -> int:
        """:data:`EXIT_CTRL_C` after SIGINT, else 0 (SIGTERM, or not stopped by a signal)."""
        return EXIT_CTRL_C if self.signum == signal.SIGINT else 0


@contextmanager
def stop_on_signals() -> Iterator[StopSignal]:
    """An event that SIGINT and SIGTERM set within the block (a node runs until it is set, and
    a Ctrl-C while it shuts down changes nothing); the previous handlers are back after it."""
    stop = StopSignal()
    previous = {
        signum: signal.signal(signum, lambda signum, _frame: stop.received(signum))
        for signum in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        yield stop
    finally:
        for signum, handler in previous.items():
            if handler is not None:  # None: set outside Python, cannot be put back
                signal.signal(signum, handler)


def describe_bus(config: BusConfig) -> str:
    """``toploc/<id>/** (mode, listen [...], connect [...])``, for the line a node prints."""
    return (
        f"toploc/{config.robot_id}/** ({config.mode}, listen {list(config.listen)}, connect "
        f"{list(config.connect)})"
    )


def check_robot_spec(_ctx: click.Context, _param: click.Parameter, value: str) -> str:
    from toploc.robots import parse_robot_spec  # only the commands that run a robot load it

    try:
        parse_robot_spec(value)
    except ValueError as error:
        raise click.BadParameter(str(error)) from None
    return value


def db_option(help: str, required: bool = True, exists: bool = False) -> Any:
    """The ``--db FILE`` option (the ``db_path`` parameter, a ``Path``; None when not given):
    the map database every command names the same way; ``exists``: click refuses a missing
    file."""
    return click.option(
        "--db",
        "db_path",
        required=required,
        default=None,
        metavar="FILE",
        type=click.Path(dir_okay=False, exists=exists, path_type=Path),
        help=help,
    )


def check_map_id_option(
    _ctx: click.Context, _param: click.Parameter, value: str | None
) -> str | None:
    """A ``--map-id`` or ``--map-from`` value: a site map's id (one key chunk), or None."""
    if value is None:
        return None
    try:
        return check_map_id(value)
    except ValueError as error:
        raise click.BadParameter(str(error)) from None


def map_from_option(more_help: str = "") -> Any:
    """The ``--map-from MAP_ID`` option (the ``map_from`` parameter; None when not given) of a
    command whose localizer runs on a replica of a site map (:func:`site_replica`)."""
    return click.option(
        "--map-from",
        "map_from",
        metavar="MAP_ID",
        default=None,
        callback=check_map_id_option,
        help="Localize on a replica of site map MAP_ID (served by toploc node map --map-id MAP_ID "
        "anywhere on the bus; docs/site.md): --db is this robot's replica (default "
        "$TOPLOC_HOME/replicas/MAP_ID.db), made from the map's snapshot and kept current"
        + more_help
        + ".",
    )


def site_replica(map_from: str, db_path: Path | None) -> Path:
    """The file of a site robot's replica of site map ``map_from``: ``--db`` if given, else
    ``$TOPLOC_HOME/replicas/<map_from>.db``."""
    return db_path or cache_dir() / "replicas" / f"{map_from}.db"


@contextmanager
def map_file(db_path: Path | None, new_map: bool) -> Iterator[Path | None]:
    """``--db`` for the block, created empty with ``--new-map``; a missing one is an error.
    A map created here and still without a room when the block raises (the command refused
    to start) is deleted: a refusal leaves no new file behind."""
    if db_path is None:
        if new_map:
            raise click.UsageError("--new-map needs --db FILE")
        yield None
        return
    created = False
    if not db_path.exists():
        if not new_map:
            raise click.BadParameter(
                f"map {db_path} does not exist (--new-map creates it empty)", param_hint="--db"
            )
        try:
            MapDatabase.open(db_path, create=True).close()
        except MapDatabaseError as error:
            raise click.ClickException(str(error)) from error
        created = True
    try:
        yield db_path
    except BaseException:
        if created:
            _delete_if_empty(db_path)
        raise


def _delete_if_empty(db_path: Path) -> None:
    """Delete the map at ``db_path`` (and its WAL files) if it holds no room."""
    try:
        with MapDatabase.open(db_path, create=False, readonly=True) as map_db:
            empty = not map_db.rooms()
    except MapDatabaseError:
        return
    if empty:
        for suffix in ("", "-wal", "-shm"):
            db_path.with_name(db_path.name + suffix).unlink(missing_ok=True)


def open_capture_source(stack: ExitStack, source: str) -> Camera | None:
    """The camera of ``--source`` (None for ``sim``: the robot's own), closed by ``stack``;
    a source that cannot be opened is a one-line error."""
    from robot.camera_sources import CameraError, open_source

    if source == "sim":
        return None
    try:
        camera = open_source(source)
    except CameraError as error:
        raise click.ClickException(f"--source: {error}") from None
    stack.callback(getattr(camera, "close", lambda: None))
    return camera


def stopped(stop: StopSignal, refresher: MapRefresher | None = None) -> None:
    """Print ``stopped`` and exit with ``stop``'s status (130 after Ctrl-C, 0 after SIGTERM);
    if a map calibration still runs in ``refresher``'s thread, end the process now (an
    interpreter exiting under a native OpenCV call aborts): the map keeps the likelihood it
    had, as SQLite writes a calibration in one transaction."""
    click.echo("stopped")
    if refresher is not None and refresher.running:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(stop.exit_code)
    if stop.exit_code:
        raise SystemExit(stop.exit_code)
