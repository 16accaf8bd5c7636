"""``toploc sim p2os``: a simulated Pioneer base speaking P2OS/ARCOS on a pseudo-terminal, for
trying the serial path without a robot (issue 12). Prints the port to connect to, runs until
Ctrl-C or SIGTERM. With ``--bus`` it also publishes its true pose and serves ``sim/kidnap`` on
the Zenoh bus (simulation only, :mod:`toploc.nodes.sim_truth`), so that ``toploc serve --robot
p2os:PORT --source sim`` in another process renders its camera where the base really is.
"""

from __future__ import annotations

from contextlib import ExitStack
from dataclasses import replace
from pathlib import Path

import click
import numpy as np

from robot.p2os_models import DEFAULT_MODEL, MODEL_FACTORS
from robot.p2os_sim import P2osSimulator, SimFaults
from robot.sim_robot import Obstacles, random_free_pose
from robot.worlds import WORLD_NAMES, make_world
from toploc.bus.config import client_bus_config
from toploc.bus.session import open_when_up
from toploc.commands.options import (
    long_running,
    robot_id_option,
    service_endpoint_option,
    stop_on_signals,
    stopped,
    zenoh_config_option,
)
from toploc.nodes.sim_truth import SimTruthNode

FAULTS = ("garbage", "truncated", "checksum", "mute")


def simulator_faults(names: tuple[str, ...], every: int) -> SimFaults:
    """The :class:`SimFaults` for ``names`` (of :data:`FAULTS`), each on every ``every``-th SIP."""
    return SimFaults(
        mute_handshake="mute" in names,
        garbage_every=every if "garbage" in names else 0,
        truncate_every=every if "truncated" in names else 0,
        bad_checksum_every=every if "checksum" in names else 0,
    )


@click.command("p2os")
@long_running
@click.option(
    "--world",
    type=click.Choice(WORLD_NAMES),
    default="building",
    show_default=True,
    help="The rendered world the base drives in (its walls stop it).",
)
@click.option("--room", default="office_b", show_default=True, help="Where the base starts.")
@click.option("--seed", type=int, default=1, show_default=True, help="Seeds the start pose.")
@click.option(
    "--link",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also make this symlink to the pty (a stable port name).",
)
@click.option(
    "--fault",
    "faults",
    type=click.Choice(FAULTS),
    multiple=True,
    help="Inject a fault (repeatable): garbage bytes, truncated or bad-checksum SIPs (every "
    "--fault-every-th SIP), or a mute handshake.",
)
@click.option(
    "--fault-every",
    type=click.IntRange(min=1),
    default=10,
    show_default=True,
    help="How often a --fault of garbage, truncated or checksum strikes: every N-th SIP.",
)
@click.option(
    "--time-scale",
    type=click.FloatRange(min=0.1, max=20),
    default=1.0,
    show_default=True,
    help="Simulated seconds per wall-clock second (2: the base moves twice as fast).",
)
@click.option(
    "--model",
    type=click.Choice(sorted(MODEL_FACTORS), case_sensitive=False),
    default=DEFAULT_MODEL,
    show_default=True,
    help="The Pioneer model the SYNC2 reply names; the SIPs are in its units (a classic p3dx "
    "counts 0.485 mm).",
)
@click.option(
    "--bus",
    "on_bus",
    is_flag=True,
    help="Also publish the true pose (sim/true_pose) and serve sim/kidnap on the Zenoh bus, "
    "for a service's sim camera (toploc serve --robot p2os:PORT --source sim). Simulation only.",
)
@robot_id_option
@service_endpoint_option
@zenoh_config_option
def p2os(
    world: str,
    room: str,
    seed: int,
    link: Path | None,
    faults: tuple[str, ...],
    fault_every: int,
    time_scale: float,
    model: str,
    on_bus: bool,
    robot_id: str,
    endpoints: tuple[str, ...],
    zenoh_file: Path | None,
) -> None:
    """Run a simulated Pioneer base on a pseudo-terminal until interrupted."""
    built = make_world(world)
    try:
        pose = random_free_pose(Obstacles.of(built, 0.2), room, np.random.default_rng([seed, 13]))
    except ValueError as error:
        raise click.ClickException(f"--room {room!r}: {error}") from error
    sim = P2osSimulator(
        built,
        pose,
        time_scale=time_scale,
        link=link,
        faults=simulator_faults(faults, fault_every),
        model=model,
    )
    with ExitStack() as stack:
        stop = stack.enter_context(stop_on_signals())  # left last: the simulator closes first
        stack.enter_context(sim)
        click.echo(f"port: {sim.port}")
        click.echo(
            f"a simulated Pioneer in {world}/{room} at ({pose.x_m:.2f}, {pose.y_m:.2f}) m; "
            f"connect with: toploc serve --robot p2os:{sim.port}. Ctrl-C stops."
        )
        if on_bus:
            try:
                # a Zenoh client: the service routes its other clients' queries to it (peers
                # that listen nowhere do not reach each other through a third)
                config = client_bus_config(robot_id, zenoh_file, endpoints or None)
                config = replace(config, mode="client")
            except ValueError as error:
                raise click.ClickException(str(error)) from None
            click.echo(f"waiting for the service at {', '.join(config.connect)} ...")
            session = open_when_up(config, stop)
            if session is not None:
                stack.enter_context(session)
                stack.enter_context(SimTruthNode(session, robot_id, sim, seed=seed))
                click.echo(f"true pose on toploc/{robot_id}/sim/true_pose (simulation only)")
        stop.wait_for_signal()
    stopped(stop)
