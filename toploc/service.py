"""Running toploc as a service: the nodes of one robot on one Zenoh session.

:func:`start_service` opens the session and declares the map node, the localizer node and,
when a robot object is given (the simulated robot here), its robot node. The localizer always
drives the robot through the bus (:class:`toploc.nodes.robot.RemoteRobot`), so a real base
running its own robot node elsewhere is used the same way.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

import zenoh

from localizer.localizer import Localizer, LocalizerConfig
from localizer.robot_protocol import Camera, Robot
from toploc import bus
from toploc.bus import BusConfig, open_session
from toploc.limits import Limits
from toploc.maps import load_map
from toploc.nodes.localizer import LocalizerNode
from toploc.nodes.mapdb import MapNode
from toploc.nodes.robot import RemoteRobot, RobotNode
from toploc.runner import LocalizationRunner


@dataclass(frozen=True)
class Service:
    """A running service: its session, the runner behind ``localizer/*`` and the map."""

    session: zenoh.Session
    config: BusConfig
    runner: LocalizationRunner
    localizer: Localizer


@contextmanager
def start_service(
    db_path: Path,
    config: BusConfig,
    robot: Robot | None = None,
    policy: str = "separating",
    localizer_config: LocalizerConfig | None = None,
    limits: Limits | None = None,
    camera: Camera | None = None,
) -> Iterator[Service]:
    """Serve the map at ``db_path`` for robot ``config.robot_id`` within ``limits``; the
    robot node (when ``robot`` is given) captures from ``camera`` if given, else the robot.

    On exit a running localization is ended (at its next capture or move), then everything is
    undeclared and the session closed (an unclosed session keeps the process alive).
    """
    localizer_config = localizer_config or LocalizerConfig()
    limits = limits or Limits()
    loaded = load_map(db_path, localizer_config.detector)
    localizer = Localizer(loaded, localizer_config)
    robot_id = config.robot_id
    with ExitStack() as stack:
        session = stack.enter_context(open_session(config))
        stack.enter_context(MapNode(session, robot_id, db_path))
        if robot is not None:
            stack.enter_context(RobotNode(session, robot_id, robot, limits, camera))
        remote = RemoteRobot(
            session, robot_id, move_timeout_s=limits.move_timeout_s + bus.DEFAULT_TIMEOUT_S,
            max_image_pixels=limits.max_image_pixels,
        )  # fmt: skip
        stack.callback(remote.close)
        runner = LocalizationRunner(
            localizer, remote, policy, max_pending=limits.max_pending_localizations
        )
        node = stack.enter_context(LocalizerNode(session, robot_id, runner, limits))
        runner.publish = node.publish
        stack.callback(runner.stop)
        yield Service(session, config, runner, localizer)
