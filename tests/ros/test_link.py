"""RosLink on real Zenoh sessions (loopback): samples, attachments, drops, graph, errors.

A plain Zenoh router stands for ``rmw_zenohd``; a raw client session plays the
other side, so what our link puts and declares is read byte for byte, and what
it is sent can be anything (no attachment, garbage CDR, tokens of another hash).
"""

from __future__ import annotations

import asyncio
import sys
import time
from collections.abc import AsyncIterator
from typing import Any

import pytest

pytest.importorskip("zenoh")
pytest.importorskip("rosbags")

from cas_async import ConfigurationError, RobotStateError
from cas_async.ros import RosLink, RosTimeout, RosTypeMismatchWarning, TypeCatalog
from cas_async.ros._attachment import Attachment
from cas_async.ros._extra import INSTALL, import_rosbags_typesys, import_zenoh
from cas_async.ros._graph import entity_gid

from .helpers import free_port, until, zenoh_session

STRING = "std_msgs/msg/String"
STRING_KEY = (
    "0/probe/std_msgs::msg::dds_::String_/"
    "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
)
NOW_NS = 1_700_000_000_000_000_000


@pytest.fixture
async def router() -> AsyncIterator[str]:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    async with zenoh_session("router", endpoint):
        yield endpoint


@pytest.fixture
async def link(router: str) -> AsyncIterator[RosLink]:
    link = RosLink("tester", connect=router, clock_ns=lambda: NOW_NS)
    try:
        await link.open()
        yield link
    finally:
        link.close()
    assert link.session is None


async def test_a_publisher_puts_cdr_with_rmw_zenoh_s_attachment(router: str, link: RosLink) -> None:
    samples: list[Any] = []
    async with zenoh_session("client", router) as other:
        subscriber = other.declare_subscriber("0/probe/**", samples.append)
        publisher = link.publisher("probe", STRING)
        await until(lambda: publisher.matched, "the other session's subscriber is known")
        for text in ("one", "two", "three"):
            publisher.publish({"data": text})
        await until(lambda: len(samples) == 3, "three samples")
        subscriber.undeclare()
    string = TypeCatalog().get(STRING)
    gid = entity_gid(publisher.entity.token())
    assert [str(s.key_expr) for s in samples] == [STRING_KEY] * 3
    assert [string.decode(s.payload.to_bytes())["data"] for s in samples] == ["one", "two", "three"]
    assert [Attachment.from_bytes(s.attachment.to_bytes()) for s in samples] == [
        Attachment(n, NOW_NS, gid) for n in (1, 2, 3)
    ]


async def test_our_node_and_endpoints_are_in_the_graph_with_their_tokens(
    router: str, link: RosLink
) -> None:
    link.publisher("/probe", STRING)
    link.subscribe("~/echo", STRING)
    tokens: list[str] = []
    async with zenoh_session("client", router) as other:
        replies = other.liveliness().get("@ros2_lv/0/**")
        tokens = sorted(str(reply.ok.key_expr) for reply in replies)
    zid = link.zid
    assert tokens == sorted(
        [
            f"@ros2_lv/0/{zid}/0/0/NN/%/%/tester",
            f"@ros2_lv/0/{zid}/0/1/MP/%/%/tester/%probe/std_msgs::msg::dds_::String_/"
            f"{STRING_KEY.rsplit('/', 1)[1]}/::,10:,:,:,,",
            f"@ros2_lv/0/{zid}/0/2/MS/%/%/tester/%tester%echo/std_msgs::msg::dds_::String_/"
            f"{STRING_KEY.rsplit('/', 1)[1]}/::,10:,:,:,,",
        ]
    )
    await until(lambda: len(link.graph()) == 3, "the link sees its own three tokens")
    assert link.nodes() == ["/tester"]


async def test_malformed_samples_are_dropped_and_counted_and_good_ones_still_arrive(
    router: str, link: RosLink, caplog: pytest.LogCaptureFixture
) -> None:
    subscription = link.subscribe("probe", STRING)
    string = TypeCatalog().get(STRING)
    good = Attachment(1, NOW_NS, bytes(16)).to_bytes()
    async with zenoh_session("client", router) as other:
        probe = other.declare_publisher(STRING_KEY)
        await until(lambda: probe.matching_status.matching, "our subscriber reached the router")
        other.put(STRING_KEY, string.encode({"data": "no attachment"}))
        other.put(STRING_KEY, string.encode({"data": "short attachment"}), attachment=b"\x01" * 10)
        other.put(STRING_KEY, b"\x00\x01\x00\x00\xff\xff\xff\x7f", attachment=good)
        for n in (2, 5):  # 3 and 4 never sent: two lost
            attachment = Attachment(n, NOW_NS, bytes(16)).to_bytes()
            other.put(STRING_KEY, string.encode({"data": f"good {n}"}), attachment=attachment)
        async with asyncio.timeout(10):
            first, second = await subscription.receive(), await subscription.receive()
    assert (first, second) == ({"data": "good 2"}, {"data": "good 5"})
    assert subscription.dropped == {"no_attachment": 1, "bad_attachment": 1, "malformed_cdr": 1}
    assert subscription.received == 2
    assert subscription.lost == 2
    assert sum("dropped" in message for message in caplog.messages) == 3


async def test_a_slow_reader_keeps_the_last_depth_messages(router: str, link: RosLink) -> None:
    from cas_async.ros import QoS

    subscription = link.subscribe("probe", STRING, qos=QoS(depth=3))
    publisher = link.publisher("probe", STRING)
    await until(lambda: publisher.matched, "the subscription is known")
    for n in range(8):
        publisher.publish({"data": str(n)})
    await until(lambda: subscription.received == 8, "eight samples")
    assert [await subscription.receive() for _ in range(3)] == [{"data": str(n)} for n in (5, 6, 7)]
    assert subscription.dropped == {"overflow": 5}
    assert subscription.latest == {"data": "7"}


async def test_a_peer_of_another_type_hash_is_warned_about_naming_both(
    router: str, link: RosLink
) -> None:
    link.subscribe("probe", STRING)
    ours = STRING_KEY.rsplit("/", 1)[1]
    async with zenoh_session("client", router) as other:
        token = other.liveliness().declare_token(
            "@ros2_lv/0/0123abcd/0/5/MP/%/%/old_talker/%probe/std_msgs::msg::dds_::String_/"
            "TypeHashNotSupported/::,10:,:,:,,"
        )
        with pytest.warns(RosTypeMismatchWarning) as warned:
            await until(lambda: bool(link.mismatches), "the mismatch is seen")
        token.undeclare()
    message = str(warned[0].message)
    assert "/old_talker" in message
    assert f"std_msgs::msg::dds_::String_/{ours}" in message
    assert "TypeHashNotSupported" in message
    assert "Humble" in message


async def test_tokens_rmw_zenoh_would_refuse_are_counted(router: str, link: RosLink) -> None:
    async with zenoh_session("client", router) as other:
        token = other.liveliness().declare_token("@ros2_lv/0/0123abcd/0/0/XX/%/%/broken")
        await until(lambda: link.bad_tokens == 1, "the bad token is counted")
        token.undeclare()
    assert all(entity.node != "broken" for entity in link.graph())


async def test_wait_for_times_out_naming_the_topic_and_the_nodes_seen(link: RosLink) -> None:
    with pytest.raises(
        RosTimeout, match=r"no ROS node publishes /odom .* within 0.3 s; nodes seen: /tester"
    ):
        await link.wait_for("odom", "MP", 0.3)


async def test_no_router_fails_within_seconds_naming_the_endpoint() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    link = RosLink(connect=endpoint, open_timeout=1.0)
    began = time.monotonic()
    with pytest.raises(
        ConfigurationError, match=rf"no Zenoh router answered at {endpoint} within 1 s"
    ):
        await link.open()
    assert time.monotonic() - began < 15  # 1 s asked; generous for a loaded machine
    assert link.session is None


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"connect": "192.168.1.20:7447"}, "PROTOCOL/HOST:PORT"),
        ({"connect": "tcp/robot"}, "PROTOCOL/HOST:PORT"),
        ({"connect": []}, "needs the router's endpoint"),
        ({"namespace": "robot1"}, "ROS namespace"),
        ({"domain_id": -1}, "domain id"),
        ({"mode": "router"}, "mode must be"),
        ({"open_timeout": 0}, "open_timeout"),
    ],
    ids=[
        "no-protocol",
        "no-port",
        "no-endpoint",
        "relative-namespace",
        "domain",
        "mode",
        "timeout",
    ],
)
def test_bad_settings_are_refused_naming_them(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ConfigurationError, match=message):
        RosLink(**kwargs)


@pytest.mark.parametrize(("given", "namespace"), [("", "/"), ("/", "/"), ("/robot1", "/robot1")])
def test_the_empty_namespace_is_the_root_as_in_rclpy(given: str, namespace: str) -> None:
    link = RosLink("probe", namespace=given)
    assert link.namespace == namespace
    assert link.resolve("cmd_vel") == f"{namespace.rstrip('/')}/cmd_vel"


def test_a_bad_node_name_is_refused() -> None:
    with pytest.raises(ConfigurationError, match="node name"):
        RosLink("my-node")


async def test_a_wrong_distribution_is_refused_before_connecting() -> None:
    link = RosLink(connect=f"tcp/127.0.0.1:{free_port()}", distro="humble")
    with pytest.raises(ConfigurationError, match="'humble' is not supported"):
        await link.open()


async def test_a_link_opens_once_and_its_endpoints_end_with_it(router: str) -> None:
    link = RosLink("tester", connect=router)
    with pytest.raises(RobotStateError, match="open it first"):
        link.publisher("probe", STRING)
    async with link:
        with pytest.raises(RobotStateError, match="a link opens once"):
            await link.open()
        subscription = link.subscribe("probe", STRING)
        publisher = link.publisher("probe", STRING)
        reader = asyncio.ensure_future(anext(aiter(subscription)))
        await asyncio.sleep(0)
    with pytest.raises(StopAsyncIteration):
        await reader
    with pytest.raises(RobotStateError, match="closed"):
        publisher.publish({"data": "late"})
    with pytest.raises(RobotStateError, match="a link opens once"):
        await link.open()


def test_without_the_extra_it_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "zenoh", None)
    monkeypatch.setitem(sys.modules, "rosbags", None)
    monkeypatch.setitem(sys.modules, "rosbags.typesys", None)
    assert INSTALL == 'pip install "cas_async[ros]"'
    for load in (import_zenoh, import_rosbags_typesys, TypeCatalog):
        with pytest.raises(ConfigurationError, match='pip install "cas_async\\[ros\\]"'):
            load()
