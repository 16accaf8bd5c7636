"""``toploc belief``: ask a running toploc service (over Zenoh) which room the robot is in.

Opens a session that listens nowhere and connects to ``--connect`` (default: the
``--zenoh-config`` file's endpoints, else ``tcp/127.0.0.1:7447``), then queries
``toploc/<robot-id>/localizer/...`` (robot id: this machine's host name unless ``--robot-id``).
``--reset`` resets the belief first, ``--localize`` (or ``--active``) localizes now, then the
belief is printed. Exit status 1 with ``Error: ...`` if no service answers or the service
reports an error.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from toploc import bus
from toploc.commands.belief_text import format_belief
from toploc.commands.bus_client import client_session
from toploc.commands.options import robot_id_option, service_endpoint_option, zenoh_config_option


@click.command("belief")
@robot_id_option
@service_endpoint_option
@zenoh_config_option
@click.option("--localize", is_flag=True, help="Localize now before printing the belief.")
@click.option("--active", is_flag=True, help="Localize and allow moving to disambiguate.")
@click.option("--reset", is_flag=True, help="Reset to a uniform belief first.")
@click.option("--json", "as_json", is_flag=True, help="Print the belief as JSON.")
@click.option(
    "--watch",
    is_flag=True,
    help="Show the belief as it changes until Ctrl-C: a bar per room, the state, the stamp and "
    "an active localization's drives (redrawn on a terminal; one block per belief when piped, "
    "one JSON line with --json). With --localize/--active: until that localization ends.",
)
@click.option(
    "--timeout",
    "timeout_s",
    type=click.FloatRange(min=0, min_open=True),
    default=bus.DEFAULT_TIMEOUT_S,
    show_default=True,
    help="Seconds to wait for an answer (localize waits up to 300 s).",
)
def belief(
    robot_id: str,
    endpoints: tuple[str, ...],
    zenoh_file: Path | None,
    localize: bool,
    active: bool,
    reset: bool,
    as_json: bool,
    watch: bool,
    timeout_s: float,
) -> None:
    """Print the belief of a running toploc service: probability per room, state, best place."""
    from toploc.nodes.localizer import LOCALIZE_TIMEOUT_S, LocalizerClient

    if watch:
        from toploc.commands.belief_watch import watch_belief

        watch_belief(robot_id, zenoh_file, endpoints, timeout_s, localize, active, reset, as_json)
        return
    try:
        with client_session(robot_id, zenoh_file, endpoints) as session:
            client = LocalizerClient(
                session, robot_id, timeout_s, localize_timeout_s=max(timeout_s, LOCALIZE_TIMEOUT_S)
            )
            result = client.reset() if reset else None
            if localize or active:
                result = client.localize(active=active)
            result = result if result is not None else client.belief()
    except bus.BusError as error:
        raise click.ClickException(str(error)) from error
    click.echo(json.dumps(result, indent=2, sort_keys=True) if as_json else format_belief(result))


if __name__ == "__main__":
    belief()
