"""``toploc demo``: the whole product on one machine, on the embedded defaults.

It makes the map of the rendered ``building`` world (once; a SQLite file in the cache), starts
the service on a Zenoh peer on 127.0.0.1 with the simulated robot kidnapped into one of the
look-alike offices, and then, as a separate client session over the bus, asks for an active
localization and prints every belief the service publishes until it is sure.
"""

from __future__ import annotations

import time
from typing import Any

import click

from robot.worlds import make_world
from toploc.bus import DEFAULT_ENDPOINT, BusConfig, BusError, open_session
from toploc.commands.belief_text import active_line, state_line
from toploc.commands.options import policy_option, robot_id_option, warn_if_exposed
from toploc.maps import ensure_world_map, kidnapped_robot
from toploc.nodes.localizer import LocalizerClient
from toploc.service import start_service

WORLD = "building"
LOOK_ALIKE = ("office_a", "office_b")


def belief_line(belief: dict[str, Any], t0: float) -> str:
    """``[  3.2 s] ambiguous: office_b 0.620, office_a 0.370, corridor 0.000``: the time since
    ``t0`` (``time.monotonic()``) and :func:`~toploc.commands.belief_text.state_line`."""
    return f"[{time.monotonic() - t0:6.1f} s] {state_line(belief)}"


@click.command("demo")
@click.option(
    "--room",
    type=click.Choice(LOOK_ALIKE),
    default="office_b",
    show_default=True,
    help="The look-alike office the robot is kidnapped into.",
)
@click.option("--seed", type=int, default=1, show_default=True, help="Seeds the kidnapped pose.")
@policy_option
@click.option(
    "--endpoint",
    default=DEFAULT_ENDPOINT,
    show_default=True,
    help="The Zenoh endpoint the demo's service listens on and its client connects to.",
)
@robot_id_option
def demo(room: str, seed: int, policy: str, endpoint: str, robot_id: str) -> None:
    """Kidnap the simulated robot into a look-alike office and watch toploc find out which."""
    click.echo(f"1/3 map of the rendered {WORLD!r} world (made once, then reused)")
    db_path = ensure_world_map(WORLD)
    click.echo(f"    {db_path}")
    world = make_world(WORLD)
    service_config = BusConfig(robot_id=robot_id, listen=(endpoint,))
    client_config = BusConfig(robot_id=robot_id, listen=(), connect=(endpoint,))
    warn_if_exposed(service_config)
    robot = kidnapped_robot(world, room, seed, db_path)
    try:
        with start_service(db_path, service_config, robot, policy, builtin_map=True):
            click.echo(f"2/3 service: Zenoh peer on {endpoint}, keys toploc/{robot_id}/**")
            with open_session(client_config) as session:
                _client_run(session, robot_id, room)
    except BusError as error:
        raise click.ClickException(str(error)) from error


def _client_run(session: Any, robot_id: str, true_room: str) -> None:
    client = LocalizerClient(session, robot_id)
    t0 = time.monotonic()
    _wait_for_service(client)
    click.echo("3/3 client: localize, active (may drive); beliefs as published:")
    client.subscribe(lambda belief: click.echo(belief_line(belief, t0)))
    final = client.localize(active=True)
    time.sleep(0.2)  # let the last publication print first
    active = active_line(final)
    if active is not None:
        click.echo(active)
    click.echo(
        f"final: {state_line(final)}; the robot was kidnapped into {true_room}: "
        f"{verdict(final, true_room)}"
    )


def verdict(final: dict[str, Any], true_room: str) -> str:
    """``right`` if the final belief names ``true_room`` as its answer (not lost), else
    ``WRONG``."""
    answered = final["state"] != "lost"
    return "right" if answered and final["top"]["room"] == true_room else "WRONG"


def _wait_for_service(client: LocalizerClient, timeout_s: float = 10.0) -> None:
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            client.belief()
            return
        except BusError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.1)
