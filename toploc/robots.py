"""The robot ``toploc serve`` serves, by ``--robot`` spec (issue 12):

- ``sim``: the simulated robot (:class:`robot.sim_robot.SimulatedRobot`), kidnapped in the world;
- ``p2os-sim``: a P2OS simulator in this process on a pty, driven through the real serial
  protocol (:class:`robot.p2os_base.P2osBase`), with a sim camera rendering at the simulated
  base's true pose: the whole loop over the real protocol;
- ``p2os:PORT[@MODEL]``: a real Pioneer base on serial port ``PORT``, its SIPs read in the units
  of the model its SYNC2 reply names, or of ``MODEL`` (e.g. ``p3dx``; :mod:`robot.p2os_models`)
  when given. It has no camera of its own: the
  service captures from ``--source`` (:mod:`robot.camera_sources`); with ``--source sim`` the
  camera is a sim camera rendering at the true pose a ``toploc sim p2os --bus`` on that port
  publishes (:func:`true_pose_camera`; simulation only).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path

from localizer.robot_protocol import Camera, Robot
from mapdb.database import MapDatabase
from robot.p2os_base import P2osBase
from robot.p2os_models import factors_for_model
from robot.p2os_robot import BaseWithCamera, NoCamera, SimCamera
from robot.p2os_sim import P2osSimulator
from robot.render import PanoramaCamera
from robot.worlds import make_world
from toploc.maps import kidnapped_robot
from toploc.nodes.sim_truth import TruePose

ROBOT_SPECS = "sim | p2os-sim | p2os:PORT[@MODEL]"


@dataclass(frozen=True)
class RobotSpec:
    """A parsed ``--robot`` spec: ``kind`` sim, p2os-sim or p2os; the serial ``port`` and the
    Pioneer ``model`` (None: the one its SYNC2 reply names) of a p2os base."""

    kind: str
    port: str | None = None
    model: str | None = None


def parse_robot_spec(spec: str) -> RobotSpec:
    """The :class:`RobotSpec` of a ``--robot`` spec; ``ValueError`` naming it otherwise (an
    unknown ``@MODEL`` included)."""
    if spec in ("sim", "p2os-sim"):
        return RobotSpec(spec)
    if spec.startswith("p2os:") and len(spec) > len("p2os:"):
        port, at, model = spec[len("p2os:") :].partition("@")
        if port and not (at and not model):
            if model:
                factors_for_model(model)  # an unknown model is refused here, naming the known
            return RobotSpec("p2os", port, model or None)
    raise ValueError(f"a robot is {ROBOT_SPECS}, got {spec!r}")


def true_pose_camera(
    world: str, robot_id: str, db_path: Path, seed: int
) -> tuple[SimCamera, TruePose]:
    """A sim camera of ``world`` rendering at the true pose a simulator in another process
    publishes (feed the :class:`TruePose` with :func:`toploc.nodes.sim_truth.
    subscribe_true_pose`); panoramas of the map's size, the default size for an empty map."""
    with MapDatabase.open(db_path, create=False, readonly=True) as map_db:
        places = map_db.places()
    built = make_world(world)
    size = (places[0].image_width_px, places[0].image_height_px) if places else None
    camera = PanoramaCamera(*size, height_m=built.camera_height_m) if size else None
    true_pose = TruePose(world, robot_id)
    return SimCamera(built, true_pose, camera, seed=seed), true_pose


@contextmanager
def open_robot(
    spec: str | None,
    world: str,
    room: str,
    seed: int,
    db_path: Path,
    camera: Camera | None = None,
) -> Iterator[tuple[Robot | None, str]]:
    """The robot of ``spec`` and a description of it (``None``: no robot, the bus's robot node
    is driven); a base is closed on exit; ``camera``: the camera of a ``p2os:PORT`` base (none
    by default). :class:`robot.p2os_base.P2osError` if a base does not connect."""
    if spec is None:
        yield None, "the bus's robot node"
        return
    parsed = parse_robot_spec(spec)
    kind, port = parsed.kind, parsed.port
    with ExitStack() as stack:
        if kind == "p2os" and port is not None:
            base = P2osBase(port, model=parsed.model)
            base.connect()
            stack.callback(base.close)
            where = f"the Pioneer on {port} ({', '.join(base.robot_strings)})"
            yield BaseWithCamera(base, camera or NoCamera(f"the base on {port}")), where
            return
        sim_robot = kidnapped_robot(make_world(world), room, seed, db_path)
        if kind == "sim":
            yield sim_robot, f"{world}/{room}"
            return
        sim = stack.enter_context(P2osSimulator(sim_robot.world, sim_robot.true_pose, seed=seed))
        base = P2osBase(sim.port)
        base.connect()
        stack.callback(base.close)
        camera = SimCamera(
            sim_robot.world,
            lambda: sim.true_pose,
            sim_robot.camera,
            sim_robot.condition,
            seed=seed,
        )
        yield BaseWithCamera(base, camera), f"{world}/{room} over P2OS on {sim.port}"


@contextmanager
def open_served_robot(
    spec: str | None,
    source: str,
    world: str,
    room: str,
    seed: int,
    db_path: Path,
    robot_id: str,
) -> Iterator[tuple[Robot | None, str, TruePose | None]]:
    """:func:`open_robot` as ``serve`` and ``node robot`` run it: ``(robot, description,
    true_pose)``; a ``p2os:PORT`` base with ``source`` ``sim`` gets the :func:`true_pose_camera`
    (feed ``true_pose`` from the bus), any other base its own camera."""
    base_camera, true_pose = None, None
    if spec is not None and parse_robot_spec(spec).kind == "p2os" and source == "sim":
        base_camera, true_pose = true_pose_camera(world, robot_id, db_path, seed)
    with open_robot(spec, world, room, seed, db_path, base_camera) as (robot, where):
        yield robot, where, true_pose
