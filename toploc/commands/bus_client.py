"""What the ``toploc`` commands that talk to a running service share (``drive``, ``belief
--watch``): the bus options and the client session they open.

The session listens nowhere and connects to ``--connect`` (default: the ``--zenoh-config``
file's endpoints, else ``tcp/127.0.0.1:7447``), for the keys of ``--robot-id``.
"""

from __future__ import annotations

import time
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
        _wait_for_a_node(session, robot_id)
        yield session


FIND_NODE_S = 2.0
"""How long a client waits for a node of its robot to be known before its first request."""


def _wait_for_a_node(session: zenoh.Session, robot_id: str, timeout_s: float = FIND_NODE_S) -> None:
    """Wait until a liveliness token of one of ``robot_id``'s nodes answers, at most
    ``timeout_s``: a client that reaches the service through a router (``serve --ros2``) links
    to it directly a few milliseconds after it opens, and a request sent before that link is up
    finds nobody. Returns at once when the service is connected directly; after the timeout the
    request goes out anyway and fails as it would have."""
    deadline_s = time.monotonic() + timeout_s
    nodes = bus.key(robot_id, "alive/**")
    while time.monotonic() < deadline_s:
        replies = session.liveliness().get(nodes, timeout=0.2)
        if any(reply.ok is not None for reply in replies):
            return
