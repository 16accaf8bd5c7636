"""A manual check, not part of the suite: toploc's ROS 2 bridge against an rmw_zenoh-compatible
Python client that none of us wrote, zenoh-ros2-sdk (PyPI, 0.1.8 here), through a router session
on 127.0.0.1. It is not a toploc dependency (it fetches .msg files from git at run time, which
this script avoids by giving it the few definitions it needs), so install it apart::

    python -m pip install --no-deps --target /tmp/zsdk zenoh-ros2-sdk==0.1.8 json5 GitPython \\
        gitdb smmap
    PYTHONPATH=.:/tmp/zsdk:tests python tests/toploc/ros2_independent_client.py

It prints what the client's own graph discovery, type hashing, subscriber and service clients
make of the bridge. Measured here (zenoh-ros2-sdk 0.1.8, eclipse-zenoh 1.10.2): it lists the
four topics and three services with their types, computes the Trigger and Empty hashes that
toploc serves on its own, gets Trigger's reply (``success=True, message='localized: kitchen
(p 0.95)'``) and Empty's, and receives the belief; its late-joiner query gets the cached
belief once pointed at the publisher (its own publisher discovery does not mangle the inner
``/`` of ``/toploc/belief_json`` as design.md says, so it finds no publisher by itself).
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

from bus_helpers import Bus, free_port, make_belief, wait_for

from toploc import bus
from toploc.bus.config import ros2_bus_config
from toploc.nodes.localizer import LocalizerNode
from toploc.nodes.ros2 import Ros2Bridge

DEFINITIONS = {
    "std_msgs/msg/String.msg": "string data\n",
    "std_srvs/srv/Trigger.srv": "---\nbool success\nstring message\n",
    "std_srvs/srv/Empty.srv": "---\n",
    "builtin_interfaces/msg/Time.msg": "int32 sec\nuint32 nanosec\n",
    "service_msgs/msg/ServiceEventInfo.msg": (
        "uint8 REQUEST_SENT = 0\nuint8 REQUEST_RECEIVED = 1\nuint8 RESPONSE_SENT = 2\n"
        "uint8 RESPONSE_RECEIVED = 3\nuint8 event_type\nbuiltin_interfaces/Time stamp\n"
        "char[16] client_gid\nint64 sequence_number\n"
    ),
}  # the std packages' own definitions (ros2/common_interfaces, ros2/rcl_interfaces)
EMPTY_MEMBER = "uint8 structure_needs_at_least_one_member"


class Service:
    def __init__(self) -> None:
        self.current = make_belief({"kitchen": 0.6, "hall": 0.4})

    def belief(self) -> dict:
        return self.current

    def localize(self, active: bool, deadline_s: float | None = None) -> dict:
        self.current = make_belief({"kitchen": 0.95, "hall": 0.05}, "localized", time.time())
        return self.current

    def reset(self, prior) -> dict:
        self.current = make_belief({"kitchen": 0.5, "hall": 0.5}, "lost", time.time())
        return self.current


def main() -> None:
    import zenoh_ros2_sdk as sdk
    from zenoh_ros2_sdk.message_registry import get_registry
    from zenoh_ros2_sdk.qos import QosDurability, QosProfile

    messages = Path(tempfile.mkdtemp())
    for name, text in DEFINITIONS.items():
        (messages / name).parent.mkdir(parents=True, exist_ok=True)
        (messages / name).write_text(text)
    get_registry(str(messages)).messages_dir = messages

    port = free_port()
    zbus = Bus()
    router_config = bus.BusConfig("ros", mode="router", listen=(f"tcp/127.0.0.1:{port}",))
    with (
        bus.open_session(router_config),
        bus.open_session(ros2_bus_config("r1", connect=(f"tcp/127.0.0.1:{port}",))) as ros,
        LocalizerNode(zbus.server, "r1", Service()),
    ):
        zbus.wait_alive("localizer")
        bridge = Ros2Bridge(zbus.client, "r1", ros)
        bridge.localizer.localize(False)
        time.sleep(2.0)
        print("topics:", sdk.get_topic_names_and_types(router_port=port, timeout=2.0))
        print("services:", sdk.get_service_names_and_types(router_port=port, timeout=2.0))
        got: list = []
        subscriber = sdk.ROS2Subscriber(
            "/toploc/belief_json", "std_msgs/msg/String", got.append, router_port=port,
            qos=QosProfile(durability=QosDurability.TRANSIENT_LOCAL, history_depth=1),
        )  # fmt: skip
        print("its publisher discovery:", subscriber._discover_publishers())
        subscriber._discover_publishers = lambda: [str(ros.info.zid())]
        subscriber._query_historical_data()
        print("late joiner:", wait_for(lambda: bool(got), 5), got[-1].data[:60] if got else None)
        trigger = sdk.ROS2ServiceClient(
            "/toploc/localize", "std_srvs/srv/Trigger", request_definition=EMPTY_MEMBER,
            response_definition="bool success\nstring message", router_port=port, timeout=10.0,
        )  # fmt: skip
        print("its Trigger key:", trigger.keyexpr)
        print("Trigger:", trigger.call())
        empty = sdk.ROS2ServiceClient(
            "/toploc/reinitialize_global_localization", "std_srvs/srv/Empty",
            request_definition=EMPTY_MEMBER, response_definition=EMPTY_MEMBER, router_port=port,
            timeout=10.0,
        )  # fmt: skip
        print("its Empty key:", empty.keyexpr)
        print("Empty:", empty.call())
        print("subscriber received:", len(got))
        bridge.close()
    os._exit(0)  # the SDK's singleton session has no close that ends its threads


if __name__ == "__main__":
    main()
