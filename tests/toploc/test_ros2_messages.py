"""toploc's belief as ROS 2 messages (:mod:`toploc.bus.ros2.messages`), and the ROS session's
configuration: what each field says, checked by decoding the CDR with rosbags."""

from __future__ import annotations

import json
import math

import pytest
from bus_helpers import make_belief

from toploc.bus.config import ROS2_LISTEN_ENDPOINT, ROS2_ROUTER_ENDPOINT, ros2_bus_config
from toploc.bus.messages import mark_stale
from toploc.bus.ros2.codec import DIAGNOSTIC_ARRAY, ROOM_BELIEF, STRING, Ros2Types
from toploc.bus.ros2.messages import (
    ERROR,
    OK,
    STALE,
    WARN,
    belief_diagnostics,
    belief_string,
    place_pose,
    room_belief,
    ros_time,
)


@pytest.fixture(scope="module")
def types() -> Ros2Types:
    return Ros2Types()


def round_trip(types: Ros2Types, message, type_name: str):
    return types.deserialize(types.serialize(message, type_name), type_name)


def test_the_json_string_is_the_belief_itself(types):
    belief = make_belief({"kitchen": 0.7, "hall": 0.3})
    assert json.loads(round_trip(types, belief_string(types, belief), STRING).data) == belief


@pytest.mark.parametrize(
    ("state", "level"), [("localized", OK), ("ambiguous", WARN), ("homing", WARN), ("lost", ERROR)]
)
def test_the_diagnostic_level_follows_the_state(types, state, level):
    belief = make_belief({"kitchen": 0.7, "hall": 0.3}, state)
    status = round_trip(types, belief_diagnostics(types, belief, "r1"), DIAGNOSTIC_ARRAY).status[0]
    assert status.level == level and status.hardware_id == "r1"
    values = {kv.key: kv.value for kv in status.values}
    assert values["state"] == state and values["top_room"] == "kitchen"
    assert float(values["probability"]) == pytest.approx(0.7)
    assert float(values["entropy_bits"]) == pytest.approx(belief["entropy_bits"])


def test_a_belief_that_waits_for_a_room_seen_in_part_says_so_in_its_diagnostics(types):
    belief = make_belief({"kitchen": 0.99, "hall": 0.01}, "ambiguous")
    belief["partly_seen"] = {"room": "kitchen", "horizon_share": 0.44, "needed_share": 0.6}
    status = round_trip(types, belief_diagnostics(types, belief, "r1"), DIAGNOSTIC_ARRAY).status[0]
    assert {kv.key: kv.value for kv in status.values}["partly_seen"] == "kitchen 0.440 0.600"


def test_a_stale_belief_is_stale_everywhere(types):
    belief = mark_stale(make_belief({"kitchen": 0.9, "hall": 0.1}, "localized"), now_s=5.0)
    status = belief_diagnostics(types, belief, "r1").status[0]
    assert status.level == STALE and status.message.startswith("stale, localized: kitchen")
    assert room_belief(types, belief).stale is True


def test_the_typed_belief_keeps_rooms_and_probabilities_in_order(types):
    belief = make_belief({"hall": 0.2, "kitchen": 0.8}, "localized", stamp=12.25)
    typed = round_trip(types, room_belief(types, belief), ROOM_BELIEF)
    assert typed.rooms == ["hall", "kitchen"]
    assert list(typed.probabilities) == pytest.approx([0.2, 0.8])
    assert (typed.stamp.sec, typed.stamp.nanosec) == (12, 250_000_000)
    assert (typed.best_room, typed.best_place_id, typed.best_place_inliers) == ("kitchen", 4, 37)


def test_a_belief_without_a_best_place_says_none(types):
    belief = {**make_belief({"hall": 0.5, "kitchen": 0.5}), "best_place": None}
    typed = room_belief(types, belief)
    assert (typed.best_room, typed.best_place_id, typed.best_place_inliers) == ("", -1, 0)


def test_the_pose_is_the_place_in_its_rooms_frame(types):
    belief = make_belief({"kitchen": 0.9, "hall": 0.1}, "localized", stamp=3.0)
    place = {"id": 4, "room": "kitchen", "x_m": 2.0, "y_m": 1.0, "heading_deg": 180.0}
    pose = place_pose(types, belief, place)
    assert pose.header.frame_id == "kitchen" and pose.header.stamp.sec == 3
    assert (pose.pose.pose.position.x, pose.pose.pose.position.y) == (2.0, 1.0)
    quaternion = pose.pose.pose.orientation
    assert 2 * math.atan2(quaternion.z, quaternion.w) == pytest.approx(math.pi)
    assert pose.pose.covariance[0] == pose.pose.covariance[7] == 1.0


def test_a_place_without_a_position_has_no_pose_and_one_without_a_heading_an_unknown_yaw(types):
    belief = make_belief({"kitchen": 1.0})
    assert place_pose(types, belief, {"id": 4, "room": "kitchen", "x_m": None, "y_m": None}) is None
    pose = place_pose(types, belief, {"id": 4, "room": "kitchen", "x_m": 1.0, "y_m": 1.0})
    assert pose.pose.covariance[35] == pytest.approx((2 * math.pi) ** 2)


def test_ros_time_splits_seconds_and_nanoseconds(types):
    stamp = ros_time(types, 1.5)
    assert (stamp.sec, stamp.nanosec) == (1, 500_000_000)
    assert (ros_time(types, None).sec, ros_time(types, None).nanosec) == (0, 0)


def test_the_ros_session_is_a_loopback_peer_of_the_router_without_multicast():
    config = ros2_bus_config("r1")
    assert config.mode == "peer" and not config.scouting_multicast
    assert config.connect == (ROS2_ROUTER_ENDPOINT,) == ("tcp/localhost:7447",)
    assert config.listen == (ROS2_LISTEN_ENDPOINT,) == ("tcp/127.0.0.1:0",)


def test_the_ros_sessions_endpoints_given_win_over_the_file(tmp_path):
    file = tmp_path / "ros.json5"
    file.write_text('{connect: {endpoints: ["tcp/10.0.0.2:7447"]}, listen: {endpoints: []}}')
    from_file = ros2_bus_config("r1", zenoh_file=file)
    assert from_file.connect == ("tcp/10.0.0.2:7447",) and from_file.listen == ()
    given = ros2_bus_config("r1", file, connect=["tcp/127.0.0.1:9000"], listen=["tcp/127.0.0.1:0"])
    assert given.connect == ("tcp/127.0.0.1:9000",) and given.listen == ("tcp/127.0.0.1:0",)
