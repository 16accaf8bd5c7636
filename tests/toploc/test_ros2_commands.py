"""``toploc node ros2`` and ``toploc serve --ros2`` as a user runs them: a process of their own,
joining a ROS router (a Python Zenoh session in router mode on 127.0.0.1 stands in for
``rmw_zenohd``), where the node ``toploc`` appears and its Trigger service answers."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

from bus_helpers import free_endpoint, make_belief, wait_for
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from test_node_commands import REPO, Node

from toploc import bus
from toploc.bus.ros2.attachment import Attachment
from toploc.nodes.localizer import LocalizerNode

TRIGGER_KEY = (
    "{domain}/{ns}toploc/localize/std_srvs::srv::dds_::Trigger_/"
    "RIHS01_eeff2cd6fa5ad9d27cdf4dec64818317839b62f212a91e6b5304b634b2062c5f"
)


def router(endpoint: str):
    return bus.open_session(bus.BusConfig("ros", mode="router", listen=(endpoint,)))


def node_tokens(session, domain: int, kind: str = "NN") -> list[str]:
    """The ROS graph's liveliness tokens of ``kind`` in ``domain`` (``NN`` nodes, ``SS``
    service servers)."""
    replies = session.liveliness().get(f"@ros2_lv/{domain}/**", timeout=1.0)
    tokens = [str(r.ok.key_expr) for r in replies if r.ok is not None]
    return [t for t in tokens if t.split("/")[5] == kind]


def call_trigger(session, key: str):
    """A Trigger call as rmw_zenoh's client makes it; the decoded response."""
    attachment = Attachment(1, time.time_ns(), bytes(16)).to_bytes()
    replies = list(session.get(key, payload=b"\x00\x01\x00\x00\x00", attachment=attachment,
                               timeout=20.0))  # fmt: skip
    assert replies and replies[0].ok is not None, replies
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg("bool success\nstring message", "std_srvs/msg/TriggerOut"))
    return store.deserialize_cdr(replies[0].ok.payload.to_bytes(), "std_srvs/msg/TriggerOut")


class Service:
    def belief(self) -> dict:
        return make_belief({"kitchen": 0.8, "hall": 0.2})

    def localize(self, active: bool, deadline_s: float | None = None) -> dict:
        return make_belief({"kitchen": 0.95, "hall": 0.05}, "localized", 5.0)

    def reset(self, prior) -> dict:
        return self.belief()


def test_node_ros2_joins_the_router_in_its_domain_and_namespace_until_stopped() -> None:
    toploc_endpoint, ros_endpoint = free_endpoint(), free_endpoint()
    with (
        bus.open_session(bus.BusConfig("n1", listen=(toploc_endpoint,))) as toploc_session,
        LocalizerNode(toploc_session, "n1", Service()),
        router(ros_endpoint) as ros,
    ):
        node = Node("ros2", "--robot-id", "n1", "--connect", toploc_endpoint, "--ros-connect",
                    ros_endpoint, "--ros-domain-id", "5", "--ros-namespace", "robot1")  # fmt: skip
        try:
            line = node.wait_ready()
            assert "ROS 2 node /robot1/toploc in domain 5" in line
            assert wait_for(lambda: bool(node_tokens(ros, 5)), 10), node.output
            assert node_tokens(ros, 5)[0].endswith("/NN/%/%robot1/toploc")
            responses = []

            def answered() -> bool:  # the node may hear of the localizer just after it joins
                responses.append(call_trigger(ros, TRIGGER_KEY.format(domain=5, ns="robot1/")))
                return bool(responses[-1].success)

            assert wait_for(answered, 20), responses[-1]
            assert "kitchen" in responses[-1].message
        finally:
            assert node.stop() == 0, "\n".join(node.output)
    assert node.output[-1] == "stopped"


def test_serve_ros2_on_a_new_map_answers_that_there_are_no_places_yet(tmp_path: Path) -> None:
    ros_endpoint = free_endpoint()
    args = ("--db", str(tmp_path / "new.db"), "--new-map", "--listen", free_endpoint(),
            "--robot-id", "s3", "--ros2", "--ros-connect", ros_endpoint)  # fmt: skip
    with router(ros_endpoint) as ros:
        serve = Node(*args, command=("serve",))
        try:
            assert "ROS 2 node /toploc in domain 0" in serve.wait_ready(60.0)
            # as a ROS client waits for the service: its token comes after its queryable (the
            # node's token comes first, and a call sent then found no queryable, once in CI)
            tokens = lambda: node_tokens(ros, 0, "SS")  # noqa: E731
            assert wait_for(lambda: any("%toploc%localize/" in t for t in tokens()), 10)
            response = call_trigger(ros, TRIGGER_KEY.format(domain=0, ns=""))
            assert response.success is False and "no places yet" in response.message
        finally:
            assert serve.stop() == 0, "\n".join(serve.output)


def test_serve_ros2_refuses_a_bus_on_the_ros_routers_port() -> None:
    result = subprocess.run(
        [sys.executable, "-m", "toploc", "serve", "--ros2", "--robot-id", "s4", "--listen",
         "tcp/127.0.0.1:7447"],
        cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, capture_output=True, text=True,
        timeout=60,
    )  # fmt: skip
    assert result.returncode == 2, result
    assert "--listen tcp/127.0.0.1:7447 is the port of the ROS router" in result.stderr


def test_serve_ros2_alone_puts_toplocs_bus_through_the_ros_router(tmp_path: Path) -> None:
    ros_endpoint = free_endpoint()
    args = ("--db", str(tmp_path / "new.db"), "--new-map", "--robot-id", "s5", "--ros2",
            "--ros-connect", ros_endpoint)  # fmt: skip
    with router(ros_endpoint) as ros:
        serve = Node(*args, command=("serve",))
        try:
            serve.wait_ready(60.0)
            assert any(f"toploc bus: through the ROS router at {ros_endpoint}" in line
                       for line in serve.output), serve.output  # fmt: skip
            assert wait_for(lambda: bool(node_tokens(ros, 0)), 10), serve.output
            client = subprocess.run(
                [sys.executable, "-m", "toploc", "belief", "--robot-id", "s5", "--connect",
                 ros_endpoint, "--json"],
                cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, capture_output=True,
                text=True, timeout=60,
            )  # fmt: skip
            # the service answered through the router: its map is new, so no places yet
            assert "toploc/s5/localizer/belief: NoPlacesYetError" in client.stderr, client
        finally:
            assert serve.stop() == 0, "\n".join(serve.output)
