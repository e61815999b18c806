"""MemoryTransport with a latency: sent at t, delivered at t + L, each instant in a fixed order."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import math
from collections.abc import Hashable, Iterator
from typing import Any

import pytest

from cas_async import (
    ConfigurationError,
    Layer,
    MemoryTransport,
    Message,
    RobotStateError,
    ScaledClock,
    UnknownRobotError,
    VirtualClock,
)
from cas_async.testing import Robots, run_until
from cas_async.transport import Endpoint
from tests.stacks import STACK_MESSAGES, Note

LATENCY = 0.25


class Sink:
    """Notes what arrives, and when (loop time)."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self.received: list[tuple[float, bytes, int | None]] = []
        self.endpoint: Endpoint | None = None
        self.fail_on: bytes | None = None

    def datagram_received(self, data: bytes, sender: int | None = None) -> None:
        self.received.append((self.loop.time(), data, sender))
        if data == self.fail_on:
            raise RuntimeError(f"sink refuses {data!r}")

    def transport_dropped(self, reason: str, detail: str) -> None:
        raise AssertionError(f"nothing should be dropped: {reason} {detail}")

    def robot_joined(self, robot_id: int) -> None:
        """Membership news: not what these tests look at."""

    def robot_left(self, robot_id: int) -> None:
        """Membership news: not what these tests look at."""

    def send(self, robot_id: int, data: bytes) -> None:
        assert self.endpoint is not None
        self.endpoint.send(robot_id, data)


async def opened(memory: MemoryTransport, *robot_ids: int) -> dict[int, Sink]:
    sinks = {}
    for robot_id in robot_ids:
        sink = sinks[robot_id] = Sink(asyncio.get_running_loop())
        sink.endpoint = await memory.open(robot_id, sink)
    return sinks


@contextlib.contextmanager
def reported() -> Iterator[list[dict[str, Any]]]:
    contexts: list[dict[str, Any]] = []
    loop = asyncio.get_running_loop()
    loop.set_exception_handler(lambda _loop, context: contexts.append(context))
    try:
        yield contexts
    finally:
        loop.set_exception_handler(None)


# -- configuration ----------------------------------------------------------------------


@pytest.mark.parametrize("latency", [-0.001, math.inf, math.nan])
def test_a_latency_that_is_no_duration_is_refused_naming_it(latency: float) -> None:
    with pytest.raises(ConfigurationError, match=f"latency must be >= 0.*{latency!r}"):
        MemoryTransport(latency=latency, clock=VirtualClock())


def test_a_latency_needs_the_robots_clock() -> None:
    with pytest.raises(ConfigurationError, match="needs the robots' clock"):
        MemoryTransport(latency=0.1)
    assert MemoryTransport(latency=0.0).latency == 0.0  # none: no clock needed


def test_the_latency_shows_in_the_repr() -> None:
    assert repr(MemoryTransport(latency=0.005, clock=VirtualClock())).endswith("latency 0.005 s)")
    assert "latency" not in repr(MemoryTransport())


# -- endpoints on virtual time ----------------------------------------------------------


@pytest.mark.cas_virtual
async def test_a_datagram_sent_at_t_arrives_at_t_plus_the_latency() -> None:
    memory = MemoryTransport(latency=LATENCY, clock=VirtualClock())
    sinks = await opened(memory, 1, 2)
    await asyncio.sleep(1.0)
    sinks[1].send(2, b"hello")
    sinks[1].send(1, b"to myself")  # a robot's own datagrams take the latency too
    await asyncio.sleep(LATENCY / 2)
    assert sinks[2].received == []
    await asyncio.sleep(LATENCY)
    assert sinks[2].received == [(1.0 + LATENCY, b"hello", 1)]
    assert sinks[1].received == [(1.0 + LATENCY, b"to myself", 1)]


@pytest.mark.cas_virtual
async def test_the_latency_is_simulated_seconds_on_a_clock_that_started_later() -> None:
    await asyncio.sleep(10.0)  # the loop's time is not the clock's
    clock = VirtualClock()
    clock.start()
    memory = MemoryTransport(latency=LATENCY, clock=clock)
    sinks = await opened(memory, 1, 2)
    await asyncio.sleep(2.0)
    sent_at = clock.now()
    sinks[1].send(2, b"x")
    await asyncio.sleep(1.0)
    ((arrived, _, _),) = sinks[2].received
    assert clock.at_loop_time(arrived) == sent_at + LATENCY


@pytest.mark.cas_virtual
async def test_one_instants_datagrams_arrive_by_sender_then_count_whatever_the_send_order() -> None:
    arrivals = []
    # Every interleaving of three senders' two datagrams each (90 of them); a sender's
    # own datagrams keep their order.
    for interleaving in sorted(set(itertools.permutations([1, 1, 2, 2, 3, 3]))):
        memory = MemoryTransport(latency=LATENCY, clock=VirtualClock())
        sinks = await opened(memory, 1, 2, 3, 4)
        per_sender = {1: [b"1a", b"1b"], 2: [b"2a", b"2b"], 3: [b"3a", b"3b"]}
        for sender in interleaving:
            sinks[sender].send(4, per_sender[sender].pop(0))
        await asyncio.sleep(2 * LATENCY)
        arrivals.append([(data, sender) for _, data, sender in sinks[4].received])
        for sink in sinks.values():
            assert sink.endpoint is not None
            sink.endpoint.close()
    assert len(arrivals) == 90
    assert all(arrival == arrivals[0] for arrival in arrivals)
    assert arrivals[0] == [(b"1a", 1), (b"1b", 1), (b"2a", 2), (b"2b", 2), (b"3a", 3), (b"3b", 3)]


@pytest.mark.cas_virtual
async def test_earlier_instants_arrive_first_whoever_sent() -> None:
    memory = MemoryTransport(latency=LATENCY, clock=VirtualClock())
    sinks = await opened(memory, 1, 2, 3)
    sinks[3].send(1, b"3 at 0")
    await asyncio.sleep(0.1)
    sinks[2].send(1, b"2 at 0.1")
    await asyncio.sleep(0.1)
    sinks[3].send(1, b"3 at 0.2")
    await asyncio.sleep(1.0)
    assert [(t, data) for t, data, _ in sinks[1].received] == [
        (pytest.approx(LATENCY), b"3 at 0"),
        (pytest.approx(0.1 + LATENCY), b"2 at 0.1"),
        (pytest.approx(0.2 + LATENCY), b"3 at 0.2"),
    ]


@pytest.mark.cas_virtual
async def test_a_datagram_in_flight_still_reaches_a_receiver_that_closed() -> None:
    memory = MemoryTransport(latency=LATENCY, clock=VirtualClock())
    sinks = await opened(memory, 1, 2)
    sinks[1].send(2, b"late")
    assert sinks[2].endpoint is not None
    sinks[2].endpoint.close()
    await asyncio.sleep(1.0)
    assert [data for _, data, _ in sinks[2].received] == [b"late"]  # its sink counts it


@pytest.mark.cas_virtual
async def test_sending_after_close_or_to_a_stranger_is_an_error_at_once() -> None:
    memory = MemoryTransport(latency=LATENCY, clock=VirtualClock())
    sinks = await opened(memory, 1, 2)
    with pytest.raises(UnknownRobotError, match="no robot 9"):
        sinks[1].send(9, b"x")
    assert sinks[1].endpoint is not None
    sinks[1].endpoint.close()
    with pytest.raises(RobotStateError, match="robot 1: endpoint is closed"):
        sinks[1].send(2, b"x")


@pytest.mark.cas_virtual
async def test_a_sink_that_raises_does_not_stop_the_deliveries_after_it() -> None:
    memory = MemoryTransport(latency=LATENCY, clock=VirtualClock())
    sinks = await opened(memory, 1, 2, 3)
    sinks[2].fail_on = b"bad"
    sinks[1].send(2, b"bad")
    sinks[1].send(3, b"fine")
    with reported() as contexts:
        await asyncio.sleep(1.0)
    assert [data for _, data, _ in sinks[3].received] == [b"fine"]
    assert [type(context["exception"]) for context in contexts] == [RuntimeError]
    assert "robot 2: sink failed" in contexts[0]["message"]


# -- scaled time ------------------------------------------------------------------------


async def test_on_scaled_time_the_latency_lasts_its_simulated_seconds_over_the_factor() -> None:
    clock = ScaledClock(time_factor=10.0)
    clock.start()
    memory = MemoryTransport(latency=0.5, clock=clock)  # 0.05 s of the loop
    sinks = await opened(memory, 1, 2)
    sent = clock.now()
    sinks[1].send(2, b"x")
    loop = asyncio.get_running_loop()
    async with asyncio.timeout(30.0):
        while not sinks[2].received:
            await asyncio.sleep(0.01)
    ((arrived, _, _),) = sinks[2].received
    # Never early (a timer may go off up to the loop's resolution before its instant).
    assert clock.at_loop_time(arrived) >= sent + 0.5 - 0.01
    assert loop.time() >= arrived


# -- robots -------------------------------------------------------------------------------


class Talker(Layer):
    """Sends ``Note``s at planned instants; records what it hears, and when; answers ``ping``."""

    def __init__(self, plan: list[tuple[float, int, str]]) -> None:
        self.plan = sorted(plan)
        self.heard: list[tuple[float, int, str]] = []

    async def inner_process(self) -> None:
        if self.plan and self.wake_due("say") is None:
            self.wake_at(self.plan[0][0], "say")

    async def on_timer(self, key: Hashable) -> None:
        now = self.clock.now()
        while self.plan and self.plan[0][0] <= now:
            _, to, text = self.plan.pop(0)
            self.send(to, Note(text, [self.robot_id]))

    async def handle_msg(self, msg: Message) -> None:
        assert isinstance(msg, Note)
        self.heard.append((self.clock.now(), msg.hops[0], msg.text))
        if msg.text == "ping":
            self.send(msg.hops[0], Note("pong", [self.robot_id]))


@pytest.mark.cas_virtual
async def test_a_robots_request_and_its_answer_take_one_latency_each(cas_robots: Robots) -> None:
    clock = VirtualClock()
    memory = MemoryTransport(latency=LATENCY, clock=clock)
    asker, answerer = Talker([(1.0, 2, "ping")]), Talker([])
    await cas_robots.start(1, [asker], transport=memory, clock=clock, messages=STACK_MESSAGES)
    await cas_robots.start(2, [answerer], transport=memory, clock=clock, messages=STACK_MESSAGES)
    await run_until(lambda: asker.heard, timeout=10.0, clock=clock)
    assert answerer.heard == [(1.0 + LATENCY, 1, "ping")]
    assert asker.heard == [(1.0 + 2 * LATENCY, 2, "pong")]


@pytest.mark.cas_virtual
@pytest.mark.parametrize("start_order", [(1, 2, 3, 4), (4, 3, 2, 1), (3, 1, 4, 2)])
async def test_what_robots_say_at_one_instant_arrives_in_one_order_however_they_were_started(
    cas_robots: Robots, start_order: tuple[int, ...]
) -> None:
    clock = VirtualClock()
    memory = MemoryTransport(latency=LATENCY, clock=clock)
    plans = {
        1: [(2.0, 4, "1: first"), (2.0, 4, "1: second"), (3.0, 4, "1: later")],
        2: [(2.0, 4, "2: only")],
        3: [(2.0, 4, "3: first"), (2.0, 4, "3: second")],
        4: [],
    }
    talkers = {robot_id: Talker(plan) for robot_id, plan in plans.items()}
    for robot_id in start_order:
        await cas_robots.start(
            robot_id, [talkers[robot_id]], transport=memory, clock=clock, messages=STACK_MESSAGES
        )
    await run_until(lambda: len(talkers[4].heard) == 6, timeout=10.0, clock=clock)
    at = 2.0 + LATENCY
    assert talkers[4].heard == [
        (at, 1, "1: first"),
        (at, 1, "1: second"),
        (at, 2, "2: only"),
        (at, 3, "3: first"),
        (at, 3, "3: second"),
        (3.0 + LATENCY, 1, "1: later"),
    ]
