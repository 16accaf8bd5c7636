"""The rmw_zenoh conventions toploc's ROS 2 bridge speaks, each pinned to where it is written:
rmw_zenoh's ``docs/design.md`` (ros2/rmw_zenoh, the rolling branch, as for Jazzy 0.2.x and
Kilted), its sources (``liveliness_utils.cpp``, ``qos.cpp``, ``attachment_helpers.cpp``), and
the type hashes published by rmw_zenoh and the ROS 2 documentation."""

from __future__ import annotations

import struct

import pytest

from toploc.bus.ros2.attachment import ATTACHMENT_BYTES, Attachment
from toploc.bus.ros2.codec import (
    EMPTY,
    ROOM_BELIEF,
    STRING,
    TRIGGER,
    Ros2Types,
    service_definitions,
)
from toploc.bus.ros2.graph import (
    LATCHED,
    PUBLISHER,
    SERVICE,
    SUBSCRIPTION,
    NodeInfo,
    QoS,
    entity_gid,
)
from toploc.bus.ros2.keys import (
    data_key,
    dds_type_name,
    fully_qualified_name,
    mangle,
)

# design.md, "Topic and Service name mapping to Zenoh key expressions": the chatter example.
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
# design.md, the same section: the add_two_ints service example.
ADD_TWO_INTS_HASH = "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"
# The issue's value, and rmw_zenoh users' tables of std_srvs (no rmw_zenoh doc names Trigger).
TRIGGER_HASH = "RIHS01_eeff2cd6fa5ad9d27cdf4dec64818317839b62f212a91e6b5304b634b2062c5f"
# The ROS 2 documentation, "Understanding services" (ros2/ros2_documentation, rolling):
# `ros2 service info -v /clear` on turtlesim prints this hash for std_srvs/srv/Empty.
EMPTY_HASH = "RIHS01_5888399dedec5ccc85ea6451949fd2c9f97bfdf963f9a588821639fcd31b5d19"


@pytest.fixture(scope="module")
def types() -> Ros2Types:
    return Ros2Types()


def test_std_msgs_string_hashes_as_published(types):
    assert types.type_hash(STRING) == STRING_HASH


@pytest.mark.parametrize(("service", "expected"), [(TRIGGER, TRIGGER_HASH), (EMPTY, EMPTY_HASH)])
def test_the_served_service_types_hash_as_published(types, service, expected):
    assert types.type_hash(service) == expected


def test_a_service_of_our_own_definition_hashes_as_rosidl_does(types):
    types.register(service_definitions(
        "example_interfaces/srv/AddTwoInts", "int64 a\nint64 b", "int64 sum"
    ))  # fmt: skip
    assert types.type_hash("example_interfaces/srv/AddTwoInts") == ADD_TWO_INTS_HASH


def test_rosbags_alone_hashes_services_wrongly_because_of_char():
    """The trap the codec fixes: rosbags' own hash keeps ServiceEventInfo's char[16]."""
    store = Ros2Types().store
    assert store.hash_rihs01(TRIGGER) != TRIGGER_HASH


def test_the_typed_belief_is_the_shipped_msg_file_with_the_issue_fields(types):
    fields = {name: desc[1] for name, desc in types.store.fielddefs[ROOM_BELIEF][1]}
    assert fields["rooms"] == ((1, ("string", 0)), 0)  # a sequence of strings
    assert fields["probabilities"] == ((1, ("float64", 0)), 0)
    assert fields["stamp"] == "builtin_interfaces/msg/Time"
    for name in ("state", "entropy_bits", "best_room", "best_place_id", "stale"):
        assert name in fields
    digest = types.type_hash(ROOM_BELIEF)
    assert digest.startswith("RIHS01_") and len(digest) == len("RIHS01_") + 64


def test_data_keys_follow_the_design_examples():
    # design.md: "0/chatter/std_msgs::msg::dds_::String_/RIHS01_df66..." and the /robot1 one.
    assert data_key(0, "/chatter", STRING, STRING_HASH) == (
        f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    )
    assert data_key(0, "/robot1/chatter", STRING, STRING_HASH).startswith("0/robot1/chatter/")
    assert data_key(2, "/add_two_ints", "example_interfaces/srv/AddTwoInts", ADD_TWO_INTS_HASH) == (
        f"2/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/{ADD_TWO_INTS_HASH}"
    )


def test_toploc_names_are_private_to_its_node():
    assert fully_qualified_name("/", "toploc", "~/belief_json") == "/toploc/belief_json"
    assert fully_qualified_name("robot1", "toploc", "~/localize") == "/robot1/toploc/localize"
    assert fully_qualified_name("/robot1", "toploc", "diagnostics") == "/robot1/diagnostics"


@pytest.mark.parametrize("bad", ["robot 1", "1robot", "a__b", "a/b c"])
def test_a_bad_namespace_is_refused_naming_it(bad):
    with pytest.raises(ValueError, match="namespace"):
        fully_qualified_name(bad, "toploc", "~/x")


def test_dds_type_names():
    assert dds_type_name("std_msgs/msg/String") == "std_msgs::msg::dds_::String_"
    assert dds_type_name("std_srvs/srv/Trigger") == "std_srvs::srv::dds_::Trigger_"
    with pytest.raises(ValueError, match="std_msgs/msg/String"):
        dds_type_name("String")


def test_the_qos_chunk_of_the_design_examples():
    # design.md, "Graph Cache": the listener's subscription is "::,10:,:,:,,", the talker's
    # publisher "::,7:,:,:,," (depth 10 and 7; qos.cpp's default depth is 42).
    assert QoS(depth=10).to_keyexpr() == "::,10:,:,:,,"
    assert QoS(depth=7).to_keyexpr() == "::,7:,:,:,,"
    assert QoS().to_keyexpr() == "::,:,:,:,,"  # rmw_zenoh's defaults: every field empty
    assert LATCHED.to_keyexpr() == ":1:,1:,:,:,,"  # transient local (1), depth 1


def test_liveliness_tokens_follow_the_design_examples():
    # design.md: "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener" and
    # ".../0/10/MS/%/%/listener/%chatter/std_msgs::msg::dds_::String_/RIHS01_df66.../::,10:,:,:,,"
    node = NodeInfo(2, "/", "listener", "aac3178e146ba6f1fc6e6a4085e77f21")
    assert node.node_token() == "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
    token = node.entity_token(
        10, SUBSCRIPTION, "/chatter", "std_msgs::msg::dds_::String_", STRING_HASH, QoS(depth=10)
    )
    assert token == (
        "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/"
        f"std_msgs::msg::dds_::String_/{STRING_HASH}/::,10:,:,:,,"
    )


def test_a_namespaced_publisher_token_mangles_its_names():
    node = NodeInfo(0, "/robot1", "toploc", "abc")
    token = node.entity_token(
        3, PUBLISHER, "/robot1/toploc/belief", "toploc_msgs::msg::dds_::RoomBelief_", "H", LATCHED
    )
    assert token.split("/")[5:10] == ["MP", "%", "%robot1", "toploc", "%robot1%toploc%belief"]
    assert mangle("/a/b") == "%a%b"


def test_a_service_server_token_has_kind_ss():
    node = NodeInfo(0, "/", "toploc", "abc")
    token = node.entity_token(
        5, SERVICE, "/toploc/localize", dds_type_name(TRIGGER), TRIGGER_HASH, QoS(depth=10)
    )
    assert "/0/5/SS/%/%/toploc/%toploc%localize/std_srvs::srv::dds_::Trigger_/" in token


def test_a_gid_is_rmw_zenohs_xxh3_of_the_token():
    """The expected GID was printed by rmw_zenoh's own ``simplified_XXH3_128bits``
    (``simplified_xxhash3.cpp``, compiled with a main that copies ``low64`` then ``high64`` as
    ``Entity::Entity`` does) for this token key."""
    token = (
        "@ros2_lv/0/abc/0/1/MP/%/%/toploc/%toploc%belief_json/std_msgs::msg::dds_::String_/"
        f"{STRING_HASH}/:1:,1:,:,:,,"
    )
    assert entity_gid(token).hex() == "59a00d2f15f369cd20d28f00cbab7b42"
    assert entity_gid("short").hex() == "89dedfe9d5127012921725952605de5a"


def test_the_attachment_is_the_33_bytes_design_md_lists():
    # design.md, "Publishers": int64 LE sequence number, int64 LE ns timestamp, one byte GID
    # length (16), the 16-byte GID.
    gid = bytes(range(16))
    data = Attachment(5, 1_700_000_000_123_456_789, gid).to_bytes()
    assert len(data) == ATTACHMENT_BYTES == 33
    assert data == struct.pack("<qqB16s", 5, 1_700_000_000_123_456_789, 16, gid)
    assert Attachment.from_bytes(data) == Attachment(5, 1_700_000_000_123_456_789, gid)


def test_a_reply_echoes_the_request_sequence_number_and_client_gid():
    request = Attachment(42, 10, b"\x07" * 16)
    reply = request.reply(now_ns=99)
    assert (reply.sequence_number, reply.gid, reply.source_timestamp_ns) == (42, b"\x07" * 16, 99)


@pytest.mark.parametrize(
    ("data", "match"),
    [(None, "no attachment"), (b"\x01" * 10, "10 bytes, not 33"),
     (struct.pack("<qqB16s", 1, 2, 15, bytes(16)), "GID|decode")],
)  # fmt: skip
def test_a_bad_attachment_is_refused_naming_what_is_wrong(data, match):
    with pytest.raises(ValueError, match=match):
        Attachment.from_bytes(data)


def test_cdr_round_trip_and_a_malformed_payload_is_named(types):
    response = types.message(f"{TRIGGER}_Response", success=True, message="kitchen")
    data = types.serialize(response, f"{TRIGGER}_Response")
    assert data[:4] == b"\x00\x01\x00\x00"  # CDR little-endian encapsulation header
    assert types.deserialize(data, f"{TRIGGER}_Response").message == "kitchen"
    with pytest.raises(ValueError, match=r"not a CDR std_srvs/srv/Trigger_Request \(2 bytes\)"):
        types.deserialize(b"\x00\x01", f"{TRIGGER}_Request")


def test_the_docs_hash_table_is_what_the_code_hashes(types):
    """docs/ros2.md's table of types and hashes cannot drift from the code."""
    import re
    from pathlib import Path

    page = (Path(__file__).resolve().parents[2] / "docs" / "ros2.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| `([a-z_]+/(?:msg|srv)/\w+)` \| `([\w:]+)` \| `(RIHS01_\w+)` \|$", page,
                      re.MULTILINE)  # fmt: skip
    assert len(rows) == 6
    for type_name, dds_name, digest in rows:
        assert (dds_type_name(type_name), types.type_hash(type_name)) == (dds_name, digest)
