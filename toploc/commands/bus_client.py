"""What the ``toploc`` commands that talk to a running service share (``drive``, ``belief
--watch``): the bus options and the client session they open.

The session listens nowhere and connects to ``--connect`` (default: the ``--zenoh-config``
file's endpoints, else ``tcp/127.0.0.1:7447``), for the keys of ``--robot-id``.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import click
import zenoh

from toploc import bus
from toploc.bus.config import client_bus_config
from toploc.commands.options import robot_id_option, service_endpoint_option, zenoh_config_option


def client_options(command: Any) -> Any:
    """``--robot-id``, ``--connect`` (``endpoints``) and ``--zenoh-config`` (``zenoh_file``):
    the options of ``toploc belief``, in its order."""
    for option in (zenoh_config_option, service_endpoint_option, robot_id_option):
        command = option(command)
    return command


@contextmanager
def client_session(
    robot_id: str, zenoh_file: Path | None, endpoints: tuple[str, ...]
) -> Iterator[zenoh.Session]:
    """The client session of the options of :func:`client_options`; a bad Zenoh file or
    endpoint is a one-line error (``click.ClickException``/``BadParameter``)."""
    try:
        cfg = client_bus_config(robot_id, zenoh_file, endpoints or None)
    except bus.ZenohConfigError as error:
        raise click.ClickException(str(error)) from None
    except ValueError as error:
        raise click.BadParameter(str(error)) from error
    with bus.open_session(cfg) as session:
        yield session
