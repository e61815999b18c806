"""Conformance with rmw_zenoh's wire format, against the examples of its docs/design.md.

The expected strings below are copied from ros2/rmw_zenoh ``docs/design.md`` (the
2025 rewrite written so that others can interoperate, rmw_zenoh#648): "Topic and
Service name mapping to Zenoh key expressions" and "Graph Cache"; the QoS and
attachment layouts from its "Publishers" section and ``liveliness_utils.cpp``.
These tests build and parse those exact strings; they need rosbags only for the
type hash.
"""

from __future__ import annotations

import struct

import pytest

from cas_async import ConfigurationError
from cas_async.ros import (
    Durability,
    GraphEntity,
    History,
    Liveliness,
    QoS,
    Reliability,
    parse_token,
)
from cas_async.ros._attachment import ATTACHMENT_SIZE, Attachment
from cas_async.ros._graph import entity_gid
from cas_async.ros._names import data_key, dds_type_name, resolve_topic, ros_type_name

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
ADD_TWO_INTS_HASH = "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"
STRING_DDS = "std_msgs::msg::dds_::String_"

# design.md, "Graph Cache", the demo_nodes_cpp examples (ROS_DOMAIN_ID=2).
LISTENER_NODE = "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
LISTENER_SUB = (
    "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/"
    f"{STRING_DDS}/{STRING_HASH}/::,10:,:,:,,"
)
TALKER_PUB = (
    "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
    f"{STRING_DDS}/{STRING_HASH}/::,7:,:,:,,"
)
SERVER = (
    "@ros2_lv/2/f9980ee0495eaafb3e38f0d19e2eae12/0/10/SS/%/%/add_two_ints_server/%add_two_ints/"
    f"example_interfaces::srv::dds_::AddTwoInts_/{ADD_TWO_INTS_HASH}/::,10:,:,:,,"
)
CLIENT = (
    "@ros2_lv/2/e1dc8d1b45ae8717fce78689cc655685/0/10/SC/%/%/add_two_ints_client/%add_two_ints/"
    f"example_interfaces::srv::dds_::AddTwoInts_/{ADD_TWO_INTS_HASH}/::,10:,:,:,,"
)


def test_the_std_msgs_string_type_hash_is_the_design_document_s() -> None:
    pytest.importorskip("rosbags")
    from cas_async.ros import TypeCatalog

    string = TypeCatalog("jazzy").get("std_msgs/msg/String")
    assert string.type_hash == STRING_HASH
    assert string.dds_name == STRING_DDS


@pytest.mark.parametrize(
    ("domain", "namespace", "topic", "key"),
    [
        (0, "/", "chatter", f"0/chatter/{STRING_DDS}/{STRING_HASH}"),
        (0, "/robot1", "chatter", f"0/robot1/chatter/{STRING_DDS}/{STRING_HASH}"),
        (0, "/", "/robot1/chatter", f"0/robot1/chatter/{STRING_DDS}/{STRING_HASH}"),
    ],
    ids=["chatter", "namespaced", "absolute"],
)
def test_topic_keys_are_the_design_document_s(
    domain: int, namespace: str, topic: str, key: str
) -> None:
    name = resolve_topic(topic, namespace, "talker")
    assert data_key(domain, name, dds_type_name("std_msgs/msg/String"), STRING_HASH) == key


def test_the_service_key_example_has_the_same_shape() -> None:
    key = data_key(
        2, "/add_two_ints", "example_interfaces::srv::dds_::AddTwoInts_", ADD_TWO_INTS_HASH
    )
    assert key == f"2/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/{ADD_TWO_INTS_HASH}"


def _entity(token: str) -> GraphEntity:
    return parse_token(token)


@pytest.mark.parametrize(
    "token",
    [LISTENER_NODE, LISTENER_SUB, TALKER_PUB, SERVER, CLIENT],
    ids=["node", "subscription", "publisher", "service", "client"],
)
def test_every_token_of_the_design_document_parses_and_is_written_back_the_same(token: str) -> None:
    assert _entity(token).token() == token


def test_a_node_token_reads_as_the_graph_cache_reads_it() -> None:
    node = parse_token(LISTENER_NODE)
    assert node == GraphEntity(
        domain_id=2,
        zid="aac3178e146ba6f1fc6e6a4085e77f21",
        node_id="0",
        entity_id="0",
        kind="NN",
        enclave="/",
        namespace="/",
        node="listener",
    )
    assert node.node_fqn == "/listener"


def test_an_entity_token_reads_with_its_topic_type_hash_and_qos() -> None:
    talker = parse_token(TALKER_PUB)
    assert (talker.kind, talker.node, talker.node_id, talker.entity_id) == (
        "MP",
        "talker",
        "0",
        "10",
    )
    assert (talker.topic, talker.type_name, talker.type_hash) == (
        "/chatter",
        STRING_DDS,
        STRING_HASH,
    )
    assert talker.qos == QoS(depth=7)
    assert parse_token(LISTENER_SUB).qos == QoS(depth=10)


def test_our_tokens_have_the_design_document_s_shape() -> None:
    """What RosLink declares for a node and a subscription, with the listener's ids."""
    zid = "aac3178e146ba6f1fc6e6a4085e77f21"
    node = GraphEntity(2, zid, "0", "0", "NN", "/", "/", "listener")
    subscription = GraphEntity(
        2, zid, "0", "10", "MS", "/", "/", "listener", "/chatter", STRING_DDS, STRING_HASH, QoS()
    )
    assert node.token() == LISTENER_NODE
    assert subscription.token() == LISTENER_SUB


def test_namespaces_and_topics_are_mangled() -> None:
    entity = GraphEntity(
        0,
        "abc",
        "0",
        "3",
        "MP",
        "/",
        "/robot1/arm",
        "driver",
        "/robot1/arm/cmd_vel",
        "geometry_msgs::msg::dds_::Twist_",
        "RIHS01_x",
        QoS(),
    )
    assert entity.token() == (
        "@ros2_lv/0/abc/0/3/MP/%/%robot1%arm/driver/%robot1%arm%cmd_vel/"
        "geometry_msgs::msg::dds_::Twist_/RIHS01_x/::,10:,:,:,,"
    )
    assert parse_token(entity.token()) == entity
    assert parse_token(entity.token()).node_fqn == "/robot1/arm/driver"


@pytest.mark.parametrize(
    ("qos", "key"),
    [
        (QoS(depth=42), "::,:,:,:,,"),  # rmw_zenoh's own defaults: every field left out
        (QoS(), "::,10:,:,:,,"),  # rclcpp's create_publisher(topic, 10)
        (
            QoS(Reliability.BEST_EFFORT, Durability.TRANSIENT_LOCAL, History.KEEP_ALL, 1),
            "2:1:2,1:,:,:,,",
        ),
        (
            QoS(
                deadline=(5, 0),
                lifespan=(60, 3000),
                liveliness=Liveliness.MANUAL_BY_TOPIC,
                lease=(0, 0),
            ),
            "::,10:5,0:60,3000:3,0,0",
        ),
    ],
    ids=["rmw-zenoh-default", "rclcpp-default", "sensor-like", "durations"],
)
def test_qos_strings_leave_out_rmw_zenoh_defaults_and_read_back(qos: QoS, key: str) -> None:
    assert qos.to_key() == key
    assert QoS.from_key(key) == qos


@pytest.mark.parametrize(
    ("token", "why"),
    [
        ("@ros2_lv/0/abc/0/0/NN/%/%", "parts"),
        ("@ros2_lv/0/abc/0/0/NN/%//listener", "empty parts"),
        ("@other/0/abc/0/0/NN/%/%/listener", "outside"),
        ("@ros2_lv/0/abc/0/0/XX/%/%/listener", "invalid entity XX"),
        ("@ros2_lv/0/abc/0/1/MP/%/%/talker/%chatter", "without its topic"),
        (TALKER_PUB.replace("::,7:,:,:,,", "::,7"), "6 ':'-separated"),
        (TALKER_PUB.replace("::,7:,:,:,,", "9::,7:,:,:,,"), "9 is not a valid Reliability"),
        (TALKER_PUB.replace("::,7:,:,:,,", "::,x7:,:,:,,"), "not an unsigned number"),
        ("@ros2_lv/zero/abc/0/0/NN/%/%/listener", "domain id"),
    ],
    ids=[
        "short",
        "empty",
        "admin-space",
        "kind",
        "no-topic",
        "qos-parts",
        "qos-enum",
        "qos-depth",
        "domain",
    ],
)
def test_tokens_rmw_zenoh_refuses_are_refused_with_the_reason(token: str, why: str) -> None:
    with pytest.raises(ValueError, match=why):
        parse_token(token)


def test_the_attachment_is_33_bytes_in_the_documented_order() -> None:
    gid = bytes(range(16))
    data = Attachment(7, 1_700_000_000_123_456_789, gid).to_bytes()
    assert len(data) == ATTACHMENT_SIZE == 33
    assert (
        data == struct.pack("<q", 7) + struct.pack("<q", 1_700_000_000_123_456_789) + b"\x10" + gid
    )
    assert Attachment.from_bytes(data) == Attachment(7, 1_700_000_000_123_456_789, gid)


@pytest.mark.parametrize(
    ("data", "why"),
    [(b"\x00" * 32, "32 bytes"), (b"\x00" * 16 + b"\x08" + b"\x00" * 16, "GID of 8 bytes")],
    ids=["short", "gid-length"],
)
def test_a_malformed_attachment_is_refused(data: bytes, why: str) -> None:
    with pytest.raises(ValueError, match=why):
        Attachment.from_bytes(data)


def test_a_gid_is_16_bytes_stable_and_distinct_per_entity() -> None:
    assert len(entity_gid(TALKER_PUB)) == 16
    assert entity_gid(TALKER_PUB) == entity_gid(TALKER_PUB)
    assert entity_gid(TALKER_PUB) != entity_gid(LISTENER_SUB)


@pytest.mark.parametrize(
    ("name", "namespace", "fqn"),
    [
        ("cmd_vel", "/", "/cmd_vel"),
        ("cmd_vel", "/robot1", "/robot1/cmd_vel"),
        ("/odom", "/robot1", "/odom"),
        ("~/status", "/robot1", "/robot1/driver/status"),
        ("~/status", "/", "/driver/status"),
        ("a/b", "/ns", "/ns/a/b"),
    ],
)
def test_topic_names_resolve_as_rcl_resolves_them(name: str, namespace: str, fqn: str) -> None:
    assert resolve_topic(name, namespace, "driver") == fqn


@pytest.mark.parametrize("name", ["", "/", "cmd vel", "2fast", "a//b", "a/", "~x"])
def test_bad_topic_names_are_refused_naming_them(name: str) -> None:
    with pytest.raises(ConfigurationError, match="ROS topic name"):
        resolve_topic(name, "/", "driver")


def test_type_names_accept_the_short_form() -> None:
    assert ros_type_name("geometry_msgs/Twist") == "geometry_msgs/msg/Twist"
    assert dds_type_name("geometry_msgs/msg/Twist") == "geometry_msgs::msg::dds_::Twist_"
    with pytest.raises(ConfigurationError, match="package/msg/Name"):
        ros_type_name("Twist")
