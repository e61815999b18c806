"""What a stranger on the robot's router can send, and what it costs (issue 44 items 5 and 6).

Samples with numbers that are not finite, or longer than the subscription takes,
are dropped by reason and never reach a layer; a drive goes on with the next good
odometry; forged tokens and mismatches cost a few log lines and a bounded list; a
stranger's token of another type, seen first, does not stop ``RosDiffDrive.start``.
Most tests need no router: a subscription is fed by hand, and a link's graph is
drained by hand (as Zenoh's thread would hand it the tokens).
"""

from __future__ import annotations

import asyncio
import logging
import math
import warnings
from collections.abc import AsyncIterator
from typing import Any

import pytest

pytest.importorskip("rosbags")

from cas_async import ConstantSpeed, Pose, ScaledClock
from cas_async.ros import (
    GraphEntity,
    RosDiffDrive,
    RosLink,
    RosSubscription,
    RosTypeMismatchWarning,
    TypeCatalog,
)
from cas_async.ros._attachment import Attachment
from cas_async.ros._endpoints import SEQUENCE_PEERS
from cas_async.ros._link import MISMATCH_LIMIT

ODOM = "nav_msgs/msg/Odometry"
TWIST = "geometry_msgs/msg/Twist"
NOW_NS = 1_700_000_000_000_000_000
GID = bytes(range(16))


def odometry(x: float, y: float = 0.0) -> dict[str, Any]:
    return {
        "header": {"frame_id": "odom"},
        "child_frame_id": "base_footprint",
        "pose": {"pose": {"position": {"x": x, "y": y}, "orientation": {"w": 1.0}}},
    }


def attachment(sequence: int, gid: bytes = GID) -> bytes:
    return Attachment(sequence, NOW_NS, gid).to_bytes()


def entity(kind: str, topic: str, type_name: str, type_hash: str, node: str = "robot") -> Any:
    return GraphEntity(0, "robotzid", "0", "1", kind, node=node, topic=topic,  # type: ignore[arg-type]
                       type_name=type_name, type_hash=type_hash)  # fmt: skip


def subscription(max_bytes: int = 4096) -> RosSubscription:
    odom = TypeCatalog().get(ODOM)
    ours = entity("MS", "/odom", odom.dds_name, odom.type_hash, "us")
    return RosSubscription(ours, odom, 10, max_bytes=max_bytes)


# -- values and sizes (item 5) --------------------------------------------------------------


def test_non_finite_and_oversize_samples_are_dropped_by_reason_and_never_reach_the_reader(
    caplog: pytest.LogCaptureFixture,
) -> None:
    odom = TypeCatalog().get(ODOM)
    sub = subscription()
    for n, x in enumerate((math.nan, math.inf, -math.inf), start=1):
        sub.deliver(odom.encode(odometry(x)), attachment(n))
    big = odom.encode({**odometry(1.0), "child_frame_id": "x" * 20_000})
    sub.deliver(big, attachment(4))
    sub.deliver(odom.encode(odometry(2.5)), attachment(5))
    assert sub.dropped == {"non_finite": 3, "oversize": 1}
    assert sub.received == 1
    assert sub.latest is not None
    assert sub.latest["pose"]["pose"]["position"]["x"] == 2.5
    assert sub.lost == 0  # dropped is not lost
    for n in range(6, 1006):  # a flood of NaN: a line at the 1st, 10th, 100th, 1000th
        sub.deliver(odom.encode(odometry(math.nan)), attachment(n))
    lines = [r for r in caplog.records if "non_finite" in r.getMessage()]
    assert len(lines) == 4
    assert "1003 so far" not in lines[-1].getMessage()
    assert "1000 so far" in lines[-1].getMessage()


def test_a_sample_over_the_limit_is_refused_before_it_is_copied() -> None:
    sub = subscription()
    assert not sub.taken(20 * 1024 * 1024)  # on Zenoh's thread: its length only
    assert sub.taken(700)
    sub.refuse_oversize(20 * 1024 * 1024)  # then counted on the loop
    assert sub.dropped == {"oversize": 1}


def test_a_type_with_a_bound_is_limited_to_it_and_one_without_to_a_mebibyte() -> None:
    types = TypeCatalog()
    assert len(types.get(TWIST).encode({})) <= (types.get(TWIST).max_size or 0) < 100
    assert types.get(ODOM).max_size is None  # its frame ids are unbounded strings


def test_per_publisher_state_is_bounded_and_a_forged_sequence_is_no_loss() -> None:
    odom = TypeCatalog().get(ODOM)
    sub = subscription()
    payload = odom.encode(odometry(1.0))
    for n in range(10_000):  # 10,000 publishers, or one stranger forging GIDs
        sub.deliver(payload, attachment(1, n.to_bytes(16, "big")))
    sub.deliver(payload, attachment(1))
    sub.deliver(payload, attachment(2**62))  # a forged jump
    assert sub.lost == 0
    assert sub.sequence_jumps == 1
    sub.deliver(payload, attachment(2**62 + 3))  # two really lost after it
    assert sub.lost == 2
    assert sub.received == 10_003


class FakeLink:
    """What ``RosDiffDrive`` asks of a link, with the graph the test sets."""

    def __init__(self, odom: list[Any]) -> None:
        self.types = TypeCatalog()
        self.distro = self.types.distro
        self.odom_peers = odom
        self.odometry: RosSubscription | None = None
        self.commands: list[Any] = []

    def resolve(self, topic: str) -> str:
        return topic if topic.startswith("/") else f"/{topic}"

    def clock_ns(self) -> int:
        return NOW_NS

    def publisher(self, topic: str, ros_type: str) -> Any:
        twist = self.types.get(ros_type)
        link = self

        class Publisher:
            entity = entity("MP", topic, twist.dds_name, twist.type_hash, "us")

            def publish(self, value: Any) -> None:
                link.commands.append(value)

            def close(self) -> None:
                pass

        return Publisher()

    def subscribe(self, topic: str, ros_type: str, **kwargs: Any) -> RosSubscription:
        self.odometry = subscription(kwargs.get("max_bytes", 4096))
        return self.odometry

    def endpoints(self, topic: str, kind: str) -> list[Any]:
        if kind == "MS":
            twist = self.types.get(TWIST)
            return [entity("MS", "/cmd_vel", twist.dds_name, twist.type_hash)]
        return list(self.odom_peers)

    async def wait_for(
        self, topic: str, kind: str, timeout: float, *, match: tuple[str, str] | None = None
    ) -> Any:
        found = [
            e for e in self.endpoints(topic, kind) if match in (None, (e.type_name, e.type_hash))
        ]
        if not found:
            from cas_async.ros import RosTimeout

            raise RosTimeout(f"none on {topic}")
        return found[0]


async def _started(
    link: FakeLink, *samples: dict[str, Any], origin: Pose | None = None
) -> RosDiffDrive:
    """A drive started on ``link``, the robot sending ``samples`` one after the other."""
    drive = RosDiffDrive(
        link,  # type: ignore[arg-type]
        7,
        ScaledClock(1.0),
        speed_profile=ConstantSpeed(0.5),
        origin=origin,
    )
    starting = asyncio.ensure_future(drive.start())
    for _ in range(10):
        await asyncio.sleep(0)
        if link.odometry is not None:
            break
    odom = TypeCatalog().get(ODOM)
    assert link.odometry is not None
    for n, sample in enumerate(samples, start=1):  # one at a time: each is read, or dropped
        link.odometry.deliver(odom.encode(sample), attachment(n))
        for _ in range(5):
            await asyncio.sleep(0)
    async with asyncio.timeout(5):
        await starting
    return drive


def _odom_peers(*hashes: str) -> list[Any]:
    odom = TypeCatalog().get(ODOM)
    return [
        entity("MP", "/odom", odom.dds_name, odom.type_hash if h == "ours" else h, node)
        for node, h in zip(("stranger", "robot"), hashes, strict=False)
    ]


async def test_a_drive_goes_on_with_the_next_good_odometry() -> None:
    link = FakeLink(_odom_peers("ours"))
    drive = await _started(link, odometry(math.nan), odometry(1.5, 2.0))
    assert drive.pose() == Pose(1.5, 2.0)
    assert link.odometry is not None
    assert link.odometry.dropped == {"non_finite": 1}
    drive.close()


async def test_a_pose_that_overflows_in_the_layers_frame_is_dropped_and_the_next_taken() -> None:
    link = FakeLink(_odom_peers("ours"))
    # Finite, but past a float's range once moved by the origin: no pose; the next one is.
    drive = await _started(link, odometry(1e308), odometry(-1e308), origin=Pose(1e308, 0.0))
    assert link.odometry is not None
    assert link.odometry.dropped == {"unusable_pose": 1}
    assert drive.pose() == Pose(0.0, 0.0)
    drive.close()


async def test_a_stranger_s_token_of_another_hash_seen_first_does_not_stop_the_start() -> None:
    link = FakeLink(_odom_peers("RIHS01_" + "0" * 64, "ours"))  # the stranger's first
    drive = await _started(link, odometry(0.5))
    assert drive.pose() == Pose(0.5, 0.0)
    drive.close()


# -- tokens and mismatches (item 6), drained by hand into a link with an endpoint ----------


def _token(kind: str, node: str, type_hash: str, zid: str = "0123abcd") -> str:
    return (
        f"@ros2_lv/0/{zid}/0/5/{kind}/%/%/{node}/%odom/nav_msgs::msg::dds_::Odometry_/"
        f"{type_hash}/::,10:,:,:,,"
    )


@pytest.fixture
async def open_link() -> AsyncIterator[RosLink]:
    """A link open on a bare router (a Zenoh router stands for rmw_zenohd)."""
    pytest.importorskip("zenoh")
    from .helpers import free_port, zenoh_session

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    async with zenoh_session("router", endpoint):
        link = RosLink("tester", connect=endpoint, clock_ns=lambda: NOW_NS)
        await link.open()
        try:
            yield link
        finally:
            link.close()


async def test_a_thousand_forged_tokens_and_mismatches_cost_a_few_lines_and_a_bounded_list(
    open_link: RosLink, caplog: pytest.LogCaptureFixture
) -> None:
    open_link.subscribe("odom", ODOM)
    bad = [(None, f"@ros2_lv/0/zid{n}/0/0/XX/%/%/broken{n}", True) for n in range(1000)]
    wrong = [(None, _token("MP", f"stranger{n}", f"RIHS01_{n:064x}"), True) for n in range(1000)]
    with warnings.catch_warnings(record=True) as warned:
        warnings.simplefilter("always")
        with caplog.at_level(logging.WARNING, logger="cas_async.ros"):
            open_link._drain([*bad, *wrong])  # type: ignore[arg-type]
    assert open_link.bad_tokens == 1000
    assert len(open_link.mismatches) == MISMATCH_LIMIT
    assert open_link.mismatches_dropped == 1000 - MISMATCH_LIMIT
    mismatch_warnings = [w for w in warned if issubclass(w.category, RosTypeMismatchWarning)]
    assert 1 <= len(mismatch_warnings) <= 10
    assert "(1000 mismatched endpoints so far)" in str(mismatch_warnings[-1].message)
    lines = [r for r in caplog.records if r.name == "cas_async.ros"]
    assert 1 <= len(lines) <= 10
    assert "1000 token(s)" in lines[-1].getMessage()
    assert len(lines) + len(mismatch_warnings) <= 20


async def test_the_graph_holds_a_bounded_number_of_strangers(open_link: RosLink) -> None:
    from cas_async.ros._link import GRAPH_LIMIT

    tokens = [
        (None, f"@ros2_lv/0/zid{n}/0/0/NN/%/%/node{n}", True) for n in range(GRAPH_LIMIT + 50)
    ]
    open_link._drain(tokens)  # type: ignore[arg-type]
    assert len(open_link.graph()) == GRAPH_LIMIT
    assert open_link.graph_overflow >= 50
    assert "/tester" in open_link.nodes()  # our own node is always there


async def test_wait_for_a_type_passes_a_stranger_of_another_hash_by(open_link: RosLink) -> None:
    odom = open_link.subscribe("odom", ODOM)
    ours = (odom.entity.type_name, odom.entity.type_hash)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RosTypeMismatchWarning)
        open_link._drain(
            [  # type: ignore[list-item]
                (None, _token("MP", "stranger", "RIHS01_" + "0" * 64, "aaaa"), True),
                (None, _token("MP", "robot", odom.entity.type_hash, "bbbb"), True),
            ]
        )
    found = await open_link.wait_for("odom", "MP", 1.0, match=ours)
    assert found.node == "robot"


async def test_samples_over_the_limit_or_not_finite_are_dropped_on_a_real_router(
    open_link: RosLink,
) -> None:
    from .helpers import until, zenoh_session

    odom_type = TypeCatalog().get(ODOM)
    odom = open_link.subscribe("odom", ODOM, max_bytes=4096)
    key = f"0/odom/{odom_type.dds_name}/{odom_type.type_hash}"
    async with zenoh_session("client", open_link.connect[0]) as stranger:
        publisher = stranger.declare_publisher(key)
        await until(lambda: publisher.matching_status.matching, "our subscriber is known")
        big = odom_type.encode({**odometry(1.0), "child_frame_id": "x" * 2_000_000})
        stranger.put(key, big, attachment=attachment(1))
        stranger.put(key, odom_type.encode(odometry(math.nan)), attachment=attachment(2))
        stranger.put(key, odom_type.encode(odometry(3.0)), attachment=attachment(3))
        async with asyncio.timeout(10):
            message = await odom.receive()
    assert message["pose"]["pose"]["position"]["x"] == 3.0
    await until(lambda: sum(odom.dropped.values()) == 2, "both bad samples counted")
    assert odom.dropped == {"oversize": 1, "non_finite": 1}
    assert SEQUENCE_PEERS == 256
