"""Real Zenoh sessions on 127.0.0.1 for the tests: a free port, a node-side and a client-side
session, and waiting for a node's liveliness token."""

import math
import socket
import time
from collections.abc import Callable

import zenoh

from localizer.belief import LocalizationState, RoomBelief
from toploc import bus

ROBOT_ID = "r1"


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def free_endpoint() -> str:
    """A Zenoh TCP endpoint on a free 127.0.0.1 port."""
    return f"tcp/127.0.0.1:{free_port()}"


def wait_for(predicate: Callable[[], bool], timeout_s: float = 3.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


def alive_nodes(session: zenoh.Session, robot_id: str = ROBOT_ID) -> set[str]:
    replies = session.liveliness().get(bus.key(robot_id, "alive/*"), timeout=1.0)
    return {str(r.ok.key_expr).rsplit("/", 1)[1] for r in replies if r.ok is not None}


class Bus:
    """A node-side session listening on a free port and a client-side session connected to it."""

    def __init__(self) -> None:
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.server = bus.open_session(bus.BusConfig(ROBOT_ID, listen=(self.endpoint,)))
        self.client = bus.open_session(bus.BusConfig(ROBOT_ID, listen=(), connect=(self.endpoint,)))

    def wait_alive(self, node: str) -> None:
        assert wait_for(lambda: node in alive_nodes(self.client)), f"{node} never became alive"


def make_belief(rooms: dict[str, float], state: str = "ambiguous", stamp: float = 1.0) -> dict:
    """A belief message as a service returns it (``RoomBelief.to_json()``): ``rooms`` maps each
    room to its probability; the best place is place 4 of the likeliest room, 37 inliers."""
    return RoomBelief(
        rooms=tuple(rooms),
        probabilities=tuple(rooms.values()),
        state=LocalizationState(state),
        entropy_bits=-sum(p * math.log2(p) for p in rooms.values() if p > 0),
        best_place_id=4,
        best_place_inliers=37,
        stamp_s=stamp,
        best_place_room=max(rooms, key=rooms.__getitem__),
    ).to_json()
