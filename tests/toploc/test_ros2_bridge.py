"""The ROS 2 bridge seen from the ROS side, with no ROS installed: the tests play rmw_zenoh's
part. A Python Zenoh session in router mode stands in for ``rmw_zenohd``; it queries the graph's
liveliness tokens, subscribes as an rmw_zenoh subscription does (the attachment required, every
payload decoded with rosbags), joins late as a transient-local subscription does (a zenoh-ext
advanced subscriber that detects late publishers), and calls the services as an rmw_zenoh client
does (the 33-byte attachment on the request, the reply matched by its sequence number and GID).
toploc's side is a real localizer node serving a fake localization service."""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field

import pytest
import zenoh
import zenoh.ext
from bus_helpers import ROBOT_ID, Bus, free_endpoint, make_belief, wait_for
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from toploc import bus
from toploc.bus.config import ros2_bus_config
from toploc.bus.ros2.attachment import Attachment
from toploc.bus.ros2.codec import room_belief_definition
from toploc.bus.schemas import PLACES
from toploc.nodes.localizer import LocalizerNode
from toploc.nodes.ros2 import Ros2Bridge, Ros2Settings

DOMAIN = 7
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
TRIGGER_HASH = "RIHS01_eeff2cd6fa5ad9d27cdf4dec64818317839b62f212a91e6b5304b634b2062c5f"
EMPTY_HASH = "RIHS01_5888399dedec5ccc85ea6451949fd2c9f97bfdf963f9a588821639fcd31b5d19"
CLIENT_GID = bytes(range(100, 116))


def ros_typestore():
    """What a ROS user's tools decode with: rosbags' Jazzy types and the shipped RoomBelief."""
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg(room_belief_definition(), "toploc_msgs/msg/RoomBelief"))
    store.register(get_types_from_msg("bool success\nstring message", "std_srvs/msg/TriggerOut"))
    return store


class FakeService:
    """The localization service: localize makes office_a likely, reset makes it uniform."""

    def __init__(self) -> None:
        self.current = make_belief({"office_a": 0.5, "office_b": 0.5})
        self.calls: list[tuple] = []

    def belief(self) -> dict:
        return self.current

    def localize(self, active: bool, deadline_s: float | None = None) -> dict:
        self.calls.append(("localize", active))
        self.current = make_belief({"office_a": 0.9, "office_b": 0.1}, "localized", 2.0)
        if active:  # what toploc.runner adds to an active localization's reply
            return {**self.current, "active": {"drives": 2, "distance_m": 1.5, "ended": "settled"}}
        return self.current

    def reset(self, prior) -> dict:
        self.calls.append(("reset", prior))
        self.current = make_belief({"office_a": 0.5, "office_b": 0.5}, "lost", 3.0)
        return self.current


def router_session(endpoint: str) -> zenoh.Session:
    return bus.open_session(bus.BusConfig(ROBOT_ID, mode="router", listen=(endpoint,)))


@dataclass
class Graph:
    """toploc's bus with a localizer node, the ROS router, and the bridge between them."""

    zbus: Bus
    service: FakeService
    localizer: LocalizerNode
    router_endpoint: str
    router: zenoh.Session
    ros_session: zenoh.Session
    bridge: Ros2Bridge
    places: list[dict] = field(default_factory=list)

    def tokens(self) -> list[str]:
        replies = self.router.liveliness().get(f"@ros2_lv/{DOMAIN}/**", timeout=1.0)
        return [str(reply.ok.key_expr) for reply in replies if reply.ok is not None]

    def token(self, kind: str, name: str, within_s: float = 0.0) -> str | None:
        """The token of a node (``NN``, by node name) or endpoint (by fully qualified name);
        asked again until ``within_s`` has passed (each liveliness query waits up to 1 s: on a
        loaded machine one query may end before the router has every token)."""
        chunk, wanted = (8, name) if kind == "NN" else (9, name.replace("/", "%"))
        deadline = time.monotonic() + within_s
        while True:
            found = [
                token for token in self.tokens()
                if token.split("/")[5] == kind and token.split("/")[chunk] == wanted
            ]  # fmt: skip
            if found or time.monotonic() >= deadline:
                return found[0] if found else None

    def data_key(self, kind: str, name: str) -> str:
        """A topic's or service's data key, from its token as a ROS graph cache reads it."""
        token = self.token(kind, name, within_s=10.0)
        assert token is not None, f"no {kind} token for {name}"
        parts = token.split("/")
        return f"{parts[1]}/{parts[9].replace('%', '/')[1:]}/{parts[10]}/{parts[11]}"

    def call(self, name: str, payload: bytes, sequence: int, attachment: bool = True):
        """Call a service as an rmw_zenoh client: the request's attachment, target all complete."""
        key = self.data_key("SS", name)
        extra = Attachment(sequence, time.time_ns(), CLIENT_GID).to_bytes() if attachment else None
        replies = list(self.router.get(
            key, payload=payload, attachment=extra, target=zenoh.QueryTarget.ALL_COMPLETE,
            timeout=5.0,
        ))  # fmt: skip
        assert len(replies) == 1
        return replies[0]


@pytest.fixture
def graph(zbus: Bus) -> Iterator[Graph]:
    service = FakeService()
    places = [{"id": 4, "room": "office_a", "x_m": 1.5, "y_m": -0.5, "heading_deg": 90.0}]
    places_key = bus.key(ROBOT_ID, bus.MAP_PLACES)
    endpoint = free_endpoint()
    with (
        LocalizerNode(zbus.server, ROBOT_ID, service) as localizer,
        router_session(endpoint) as router,
        bus.open_session(ros2_bus_config(ROBOT_ID, connect=(endpoint,))) as ros_session,
    ):
        map_places = bus.serve(
            zbus.server, places_key, lambda _p: bus.Reply(PLACES.encode({"places": places}))
        )
        zbus.wait_alive("localizer")
        bridge = Ros2Bridge(zbus.client, ROBOT_ID, ros_session, Ros2Settings(DOMAIN))
        g = Graph(zbus, service, localizer, endpoint, router, ros_session, bridge, places)
        assert wait_for(lambda: g.token("NN", "toploc") is not None, 5), "the node never showed"
        yield g
        bridge.close()
        map_places.undeclare()


def test_the_graph_shows_the_node_its_publishers_and_services_with_types_and_hashes(graph):
    expected = {
        "%toploc%belief_json": ("MP", "std_msgs::msg::dds_::String_", STRING_HASH),
        "%diagnostics": ("MP", "diagnostic_msgs::msg::dds_::DiagnosticArray_", None),
        "%toploc%belief": ("MP", "toploc_msgs::msg::dds_::RoomBelief_", None),
        "%toploc%pose": ("MP", "geometry_msgs::msg::dds_::PoseWithCovarianceStamped_", None),
        "%toploc%localize": ("SS", "std_srvs::srv::dds_::Trigger_", TRIGGER_HASH),
        "%toploc%localize_active": ("SS", "std_srvs::srv::dds_::Trigger_", TRIGGER_HASH),
        "%toploc%reinitialize_global_localization": (
            "SS", "std_srvs::srv::dds_::Empty_", EMPTY_HASH,
        ),
    }  # fmt: skip
    tokens: list[str] = []

    def every_endpoint_shows() -> bool:  # one liveliness query may end before the router has all
        tokens[:] = graph.tokens()
        return {t.split("/")[9] for t in tokens if t.split("/")[5] != "NN"} >= set(expected)

    wait_for(every_endpoint_shows, 10)
    zid = str(graph.ros_session.info.zid())
    assert f"@ros2_lv/{DOMAIN}/{zid}/0/0/NN/%/%/toploc" in tokens
    by_name = {t.split("/")[9]: t.split("/") for t in tokens if t.split("/")[5] != "NN"}
    assert set(by_name) == set(expected)
    for name, (kind, dds_type, type_hash) in expected.items():
        parts = by_name[name]
        assert (parts[5], parts[10]) == (kind, dds_type), name
        assert parts[11].startswith("RIHS01_") and type_hash in (None, parts[11]), name
        assert parts[12] == (":1:,1:,:,:,," if kind == "MP" else "::,10:,:,:,,"), name


def test_a_subscriber_that_insists_on_the_attachment_decodes_every_belief(graph):
    store = ros_typestore()
    received: dict[str, list] = {"json": [], "diag": [], "typed": [], "pose": []}
    topics = {
        "json": ("/toploc/belief_json", "std_msgs/msg/String"),
        "diag": ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
        "typed": ("/toploc/belief", "toploc_msgs/msg/RoomBelief"),
        "pose": ("/toploc/pose", "geometry_msgs/msg/PoseWithCovarianceStamped"),
    }
    lock = threading.Lock()

    def subscriber(which: str):
        def on_sample(sample: zenoh.Sample) -> None:
            raw = None if sample.attachment is None else sample.attachment.to_bytes()
            attachment = Attachment.from_bytes(raw)  # rmw_zenoh drops a sample without one
            message = store.deserialize_cdr(sample.payload.to_bytes(), topics[which][1])
            with lock:
                received[which].append((attachment, message))

        return graph.router.declare_subscriber(
            graph.data_key("MP", topics[which][0]), zenoh.handlers.Callback(on_sample)
        )

    assert wait_for(lambda: graph.bridge.last_published == graph.service.current, 5)
    subscribers = [subscriber(which) for which in topics]
    time.sleep(0.3)  # the subscriptions reach the bridge's peer through the router
    graph.bridge.localizer.localize(active=False)

    def localized_everywhere() -> bool:
        with lock:
            last = [received[w][-1][1] if received[w] else None for w in topics]
        if any(m is None for m in last):
            return False
        text, diag, typed, _pose = last
        return json.loads(text.data)["state"] == typed.state == "localized" and (
            diag.status[0].level == 0
        )

    assert wait_for(localized_everywhere, 5), {k: len(v) for k, v in received.items()}
    (_, text), (_, diag), (attachment, typed), (_, pose) = (received[w][-1] for w in topics)
    assert json.loads(text.data)["state"] == "localized"
    status = diag.status[0]
    assert status.level == 0 and "office_a" in status.message
    assert {kv.key: kv.value for kv in status.values}["top_room"] == "office_a"
    assert typed.rooms == ["office_a", "office_b"] and typed.probabilities[0] == pytest.approx(0.9)
    assert (typed.state, typed.best_place_id, typed.stamp.sec) == ("localized", 4, 2)
    assert pose.header.frame_id == "office_a"
    assert (pose.pose.pose.position.x, pose.pose.pose.position.y) == (1.5, -0.5)
    assert pose.pose.pose.orientation.z == pytest.approx(2**-0.5)  # 90 degrees about z
    assert attachment.gid == graph.bridge.belief.gid
    sequences = [a.sequence_number for a, _ in received["typed"]]
    assert sequences == sorted(sequences) and sequences[0] >= 1
    for subscriber_ in subscribers:
        subscriber_.undeclare()


def test_a_late_joiner_gets_the_latest_belief(graph):
    graph.bridge.localizer.localize(active=False)
    assert wait_for(lambda: graph.bridge.last_published == graph.service.current, 5)
    store = ros_typestore()
    got: list = []
    late = zenoh.ext.declare_advanced_subscriber(
        graph.router, graph.data_key("MP", "/toploc/belief"),
        zenoh.handlers.Callback(lambda s: got.append(s)),
        history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=1),
        subscriber_detection=True,
    )  # fmt: skip
    assert wait_for(lambda: bool(got), 5), "the late joiner got nothing"
    sample = got[-1]
    Attachment.from_bytes(sample.attachment.to_bytes())
    message = store.deserialize_cdr(sample.payload.to_bytes(), "toploc_msgs/msg/RoomBelief")
    assert message.state == "localized" and message.probabilities[0] == pytest.approx(0.9)
    late.undeclare()


def trigger_request() -> bytes:
    return b"\x00\x01\x00\x00\x00"  # CDR of an empty request: its one uint8 member


def test_trigger_localize_replies_with_the_room_and_state_and_echoes_the_attachment(graph):
    reply = graph.call("/toploc/localize", trigger_request(), sequence=41)
    assert reply.ok is not None
    attachment = Attachment.from_bytes(reply.ok.attachment.to_bytes())
    assert (attachment.sequence_number, attachment.gid) == (41, CLIENT_GID)
    response = ros_typestore().deserialize_cdr(
        reply.ok.payload.to_bytes(), "std_srvs/msg/TriggerOut"
    )
    assert response.success is True
    assert "localized" in response.message and "office_a" in response.message
    assert graph.service.calls == [("localize", False)]


def test_the_active_variant_localizes_actively(graph):
    reply = graph.call("/toploc/localize_active", trigger_request(), sequence=1)
    assert reply.ok is not None
    assert graph.service.calls == [("localize", True)]
    response = ros_typestore().deserialize_cdr(
        reply.ok.payload.to_bytes(), "std_srvs/msg/TriggerOut"
    )
    assert response.message.endswith("; 2 drives, 1.50 m, ended: settled")
    assert "active" not in (graph.bridge.last_published or {})


def test_reinitialize_global_localization_resets_to_uniform(graph):
    reply = graph.call("/toploc/reinitialize_global_localization", trigger_request(), sequence=3)
    assert reply.ok is not None
    assert Attachment.from_bytes(reply.ok.attachment.to_bytes()).sequence_number == 3
    assert reply.ok.payload.to_bytes() == trigger_request()  # Empty's response: one zero byte
    assert graph.service.calls == [("reset", None)]


@pytest.mark.parametrize("payload", [b"", b"\x00\x01", b"not cdr at all"])
def test_a_malformed_trigger_request_gets_success_false_naming_it(graph, payload):
    reply = graph.call("/toploc/localize", payload, sequence=9)
    response = ros_typestore().deserialize_cdr(
        reply.ok.payload.to_bytes(), "std_srvs/msg/TriggerOut"
    )
    assert response.success is False
    assert "malformed request" in response.message and "Trigger_Request" in response.message
    assert graph.service.calls == []
    assert graph.call("/toploc/localize", trigger_request(), sequence=10).ok is not None


def test_a_request_without_the_attachment_is_refused_and_not_served(graph):
    reply = graph.call("/toploc/localize", trigger_request(), sequence=1, attachment=False)
    assert reply.err is not None and b"no attachment" in reply.err.payload.to_bytes()
    assert graph.service.calls == []


def test_the_bridge_follows_the_localizer_going_and_coming_back(graph):
    graph.bridge.localizer.localize(active=False)
    assert wait_for(lambda: (graph.bridge.last_published or {}).get("state") == "localized", 5)
    graph.localizer.close()
    assert wait_for(lambda: not graph.bridge.localizer_up, 5)
    assert wait_for(lambda: (graph.bridge.last_published or {}).get("stale") is True, 5)
    reply = graph.call("/toploc/localize", trigger_request(), sequence=2)
    response = ros_typestore().deserialize_cdr(
        reply.ok.payload.to_bytes(), "std_srvs/msg/TriggerOut"
    )
    assert response.success is False and "not on the bus" in response.message
    with LocalizerNode(graph.zbus.server, ROBOT_ID, graph.service):
        assert wait_for(lambda: graph.bridge.localizer_up, 5)
        assert wait_for(lambda: "stale" not in (graph.bridge.last_published or {"stale": 1}), 5)


def test_a_call_that_comes_before_the_bridge_heard_the_localizer_is_served(graph, monkeypatch):
    # as when a ROS client calls just after `toploc serve --ros2` started: the liveliness
    # subscriber's history has not reached the bridge yet (here it never will)
    graph.bridge.close()
    monkeypatch.setattr(Ros2Bridge, "_on_localizer_token", lambda _self, _sample: None)
    graph.bridge = Ros2Bridge(graph.zbus.client, ROBOT_ID, graph.ros_session, Ros2Settings(DOMAIN))
    assert not graph.bridge.localizer_up
    reply = graph.call("/toploc/localize", trigger_request(), sequence=5)
    response = ros_typestore().deserialize_cdr(
        reply.ok.payload.to_bytes(), "std_srvs/msg/TriggerOut"
    )
    assert response.success is True and "office_a" in response.message
    assert graph.service.calls == [("localize", False)]


class HeldService(FakeService):
    """A service whose belief, taken when asked, is answered only once ``release`` is set."""

    def __init__(self) -> None:
        super().__init__()
        self.asked = threading.Event()
        self.release = threading.Event()

    def belief(self) -> dict:
        answer = self.current
        self.asked.set()
        self.release.wait(10)
        return answer


def test_an_answer_older_than_a_belief_published_meanwhile_does_not_replace_it(graph, caplog):
    caplog.set_level(logging.INFO, logger="toploc.nodes.ros2")
    held = HeldService()
    graph.localizer.close()  # the localizer restarts: the bridge asks the new one its belief
    with LocalizerNode(graph.zbus.server, ROBOT_ID, held) as restarted:
        assert held.asked.wait(5), "the bridge never asked the restarted localizer"
        restarted.publish(held.localize(active=False))  # a newer belief, while the answer is out
        assert wait_for(lambda: graph.bridge.last_published == held.current, 5)
        held.release.set()
        assert wait_for(
            lambda: (
                "is not published" in caplog.text or graph.bridge.last_published != held.current
            ),
            5,
        )
        assert graph.bridge.last_published == held.current


def test_a_topic_whose_put_fails_does_not_keep_the_others_and_the_belief_is_put_again(graph):
    assert wait_for(lambda: graph.bridge.last_published == graph.service.current, 5)
    put: dict[str, list] = {"typed": []}
    failing = {"fail": True}

    def diagnostics_put(_message) -> None:
        if failing["fail"]:
            raise zenoh.ZError("Undeclared publisher")

    graph.bridge.belief_json.put = lambda _message: None
    graph.bridge.diagnostics.put = diagnostics_put
    graph.bridge.belief.put = put["typed"].append
    belief = make_belief({"office_a": 0.8, "office_b": 0.2}, stamp=5.0)

    def typed_puts() -> int:  # the localizer's own publications may come in between
        return sum(message.stamp.sec == 5 for message in put["typed"])

    assert graph.bridge.publish(belief)
    assert typed_puts() == 1  # the topic after the failing one was put too
    assert graph.bridge.publish(belief)  # not taken as carried already: put again
    assert typed_puts() == 2
    failing["fail"] = False
    assert graph.bridge.publish(belief)
    assert typed_puts() == 3


def test_a_router_that_goes_away_and_comes_back_is_rejoined(graph):
    graph.router.close()
    graph.router = router_session(graph.router_endpoint)
    assert wait_for(lambda: graph.token("NN", "toploc") is not None, 10), "never rejoined"
    got: list = []
    sub = graph.router.declare_subscriber(
        graph.data_key("MP", "/toploc/belief_json"), zenoh.handlers.Callback(got.append)
    )
    time.sleep(0.3)
    graph.bridge.localizer.localize(active=False)
    assert wait_for(lambda: bool(got), 5)
    sub.undeclare()


def test_a_bridge_started_before_the_router_joins_it_when_it_comes(zbus):
    endpoint = free_endpoint()
    with (
        LocalizerNode(zbus.server, ROBOT_ID, FakeService()),
        bus.open_session(ros2_bus_config(ROBOT_ID, connect=(endpoint,))) as ros_session,
        Ros2Bridge(zbus.client, ROBOT_ID, ros_session, Ros2Settings(DOMAIN)),
        router_session(endpoint) as router,
    ):

        def node_seen() -> bool:
            replies = router.liveliness().get(f"@ros2_lv/{DOMAIN}/**", timeout=1.0)
            return any(r.ok is not None and "/NN/" in str(r.ok.key_expr) for r in replies)

        assert wait_for(node_seen, 10)
