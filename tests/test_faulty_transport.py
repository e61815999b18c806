"""FaultyTransport: loss, duplicates, reordering and delay on the sending side, seeded."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

import pytest

import cas_async
from cas_async import (
    Clock,
    Faults,
    FaultyTransport,
    MemoryTransport,
    RobotStateError,
    ScaledClock,
    UdpTransport,
    UnknownRobotError,
    VirtualClock,
)
from cas_async.transport import Endpoint

T = TypeVar("T")


class RecordingSink:
    """Records ``(loop time, data, sender)`` of each arrival, and the transport's drops."""

    def __init__(self) -> None:
        self.arrivals: list[tuple[float, bytes, int | None]] = []
        self.dropped: list[str] = []
        self.event = asyncio.Event()
        self.expect = 0

    def datagram_received(self, data: bytes, sender: int | None = None) -> None:
        self.arrivals.append((asyncio.get_running_loop().time(), data, sender))
        if len(self.arrivals) >= self.expect:
            self.event.set()

    def transport_dropped(self, reason: str, detail: str) -> None:
        self.dropped.append(reason)

    def robot_joined(self, robot_id: int) -> None:
        """Membership news: not what these tests look at."""

    def robot_left(self, robot_id: int) -> None:
        """Membership news: not what these tests look at."""

    @property
    def received(self) -> list[bytes]:
        return [data for _, data, _ in self.arrivals]


Wire = tuple[FaultyTransport, Endpoint, Endpoint, RecordingSink]


async def wire(faults: Faults, **kwargs: Any) -> Wire:
    """Robot 1 sends to robot 2 over a faulty MemoryTransport."""
    transport = FaultyTransport(MemoryTransport(), faults, **kwargs)
    sink = RecordingSink()
    receiver = await transport.open(2, sink)
    sender = await transport.open(1, RecordingSink())
    return transport, sender, receiver, sink


def virtual(make: Callable[[], Awaitable[T]]) -> T:
    """Runs ``make()`` on the virtual-time loop: timers fire at once, in order."""

    async def main() -> T:
        return await make()

    return cas_async.run(main(), virtual=True)


def numbered(count: int) -> list[bytes]:
    return [b"%d" % k for k in range(count)]


async def send_all(sender: Endpoint, payloads: list[bytes], then: float = 10.0) -> None:
    """Sends every payload at once, then lets ``then`` seconds of (virtual) time pass."""
    for data in payloads:
        sender.send(2, data)
    await asyncio.sleep(then)


def stats(**nonzero: int) -> dict[str, int]:
    counts = dict.fromkeys(
        ("sent", "lost", "duplicated", "reordered", "delayed", "lost_at_close"), 0
    )
    return {**counts, **nonzero}


# -- what each fault does ------------------------------------------------------------------


def test_no_faults_pass_everything_in_order_at_once() -> None:
    async def main() -> tuple[Wire, float]:
        net = await wire(Faults())
        start = asyncio.get_running_loop().time()
        await send_all(net[1], numbered(50))
        return net, start

    (transport, _, _, sink), start = virtual(main)
    assert sink.received == numbered(50)
    assert {t for t, _, _ in sink.arrivals} == {start}
    assert {sender for _, _, sender in sink.arrivals} == {1}
    assert transport.stats == stats(sent=50)


def test_loss_1_loses_everything_and_counts_it() -> None:
    async def main() -> Wire:
        net = await wire(Faults(loss=1.0))
        await send_all(net[1], numbered(100))
        return net

    transport, _, _, sink = virtual(main)
    assert sink.arrivals == []
    assert transport.stats == stats(sent=100, lost=100)


def test_duplicate_1_delivers_each_datagram_twice() -> None:
    async def main() -> Wire:
        net = await wire(Faults(duplicate=1.0))
        await send_all(net[1], numbered(3))
        return net

    transport, _, _, sink = virtual(main)
    assert sink.received == [b"0", b"0", b"1", b"1", b"2", b"2"]
    assert transport.stats == stats(sent=3, duplicated=3)


def test_a_held_back_datagram_is_overtaken_by_the_next_one() -> None:
    async def main() -> Wire:
        net = await wire(Faults(reorder=1.0))
        transport, sender, _, _ = net
        sender.send(2, b"first")
        transport.faults = Faults()  # conditions change: the next one goes straight through
        sender.send(2, b"second")
        sender.send(2, b"third")
        await asyncio.sleep(1)
        return net

    transport, _, _, sink = virtual(main)
    assert sink.received == [b"second", b"first", b"third"]
    assert transport.stats == stats(sent=3, reordered=1)


def test_a_held_back_datagram_nothing_overtakes_goes_after_hold() -> None:
    async def main() -> tuple[Wire, float]:
        net = await wire(Faults(reorder=1.0), hold=0.25)
        start = asyncio.get_running_loop().time()
        net[1].send(2, b"alone")
        await asyncio.sleep(1)
        return net, start

    (transport, _, _, sink), start = virtual(main)
    assert sink.received == [b"alone"]
    assert sink.arrivals[0][0] - start == pytest.approx(0.25)
    assert transport.stats == stats(sent=1, reordered=1)


def test_reordering_mixes_but_keeps_every_datagram() -> None:
    async def main() -> Wire:
        net = await wire(Faults(reorder=0.3), seed=5)
        await send_all(net[1], numbered(200))
        return net

    transport, _, _, sink = virtual(main)
    assert sorted(sink.received) == sorted(numbered(200))
    assert sink.received != numbered(200)
    overtaken = sum(int(a) > int(b) for a, b in zip(sink.received, sink.received[1:], strict=False))
    assert overtaken > 0
    assert 30 < transport.stats["reordered"] < 90


@pytest.mark.parametrize(
    ("clock", "loop_seconds_per_sim_second"),
    [
        pytest.param(None, 1.0, id="no-clock-loop-seconds"),
        pytest.param(VirtualClock(), 1.0, id="virtual-clock"),
        pytest.param(ScaledClock(10.0), 0.1, id="scaled-clock-x10"),
    ],
)
def test_delay_is_drawn_in_min_max_simulated_seconds(
    clock: Clock | None, loop_seconds_per_sim_second: float
) -> None:
    async def main() -> tuple[Wire, float]:
        net = await wire(Faults(delay=(0.5, 1.5)), clock=clock, seed=3)
        start = asyncio.get_running_loop().time()
        await send_all(net[1], numbered(300))
        return net, start

    (transport, _, _, sink), start = virtual(main)
    delays = [(t - start) / loop_seconds_per_sim_second for t, _, _ in sink.arrivals]
    assert len(delays) == 300
    assert all(0.5 - 1e-9 <= d <= 1.5 + 1e-9 for d in delays)
    assert min(delays) < 0.6
    assert max(delays) > 1.4
    assert transport.stats == stats(sent=300, delayed=300)


# -- determinism ------------------------------------------------------------------------------

ROUGH = Faults(loss=0.2, duplicate=0.2, reorder=0.2, delay=(0.0, 0.1))


def rough_run(seed: int) -> tuple[list[tuple[float, bytes, int | None]], dict[str, int]]:
    async def main() -> Wire:
        net = await wire(ROUGH, seed=seed)
        await send_all(net[1], numbered(300))
        return net

    transport, _, _, sink = virtual(main)
    return sink.arrivals, transport.stats


def test_the_same_seed_gives_the_same_faults_another_seed_others() -> None:
    first, again, other = rough_run(7), rough_run(7), rough_run(8)
    assert again == first
    assert other[0] != first[0]
    arrivals, counts = first
    # Everything sent either arrived or was counted: nothing vanishes silently.
    assert len(arrivals) == counts["sent"] + counts["duplicated"] - counts["lost"]
    assert all(counts[key] > 0 for key in ("lost", "duplicated", "reordered", "delayed"))


def test_loss_rate_over_10k_sends_is_close_to_the_setting() -> None:
    async def main() -> Wire:
        net = await wire(Faults(loss=0.25), seed=11)
        await send_all(net[1], numbered(10_000))
        return net

    transport, _, _, sink = virtual(main)
    lost = transport.stats["lost"]
    # sd = sqrt(10000 * 0.25 * 0.75) ~ 43: +-200 is over 4 sd (and the seed fixes it anyway)
    assert abs(lost - 2_500) < 200
    assert len(sink.arrivals) == 10_000 - lost


# -- the endpoint contract and closing ---------------------------------------------------------


def test_an_unknown_robot_raises_even_when_the_datagram_would_be_lost() -> None:
    async def main() -> Wire:
        net = await wire(Faults(loss=1.0))
        with pytest.raises(UnknownRobotError, match="robot 99"):
            net[1].send(99, b"nobody")
        return net

    transport, _, _, _ = virtual(main)
    assert transport.stats == stats()


def test_a_closed_endpoint_refuses_to_send() -> None:
    async def main() -> None:
        _, sender, _, _ = await wire(Faults(loss=1.0))
        sender.close()
        sender.close()  # idempotent
        with pytest.raises(RobotStateError, match="closed"):
            sender.send(2, b"late")

    virtual(main)


def test_close_drops_delayed_and_held_back_copies_and_counts_them() -> None:
    async def main() -> Wire:
        net = await wire(Faults(delay=(1.0, 1.0)))
        transport, sender, _, _ = net
        for data in numbered(4):
            sender.send(2, data)
        transport.faults = Faults(reorder=1.0)
        for data in (b"a", b"b", b"c"):  # a goes when b is sent, b when c is; c is held
            sender.send(2, data)
        sender.close()
        await asyncio.sleep(5)
        return net

    transport, _, _, sink = virtual(main)
    assert sink.received == [b"a", b"b"]
    assert transport.stats == stats(sent=7, delayed=4, reordered=3, lost_at_close=5)


def test_a_delayed_copy_whose_peer_left_is_lost_not_raised() -> None:
    async def main() -> tuple[Wire, list[dict[str, Any]]]:
        errors: list[dict[str, Any]] = []
        asyncio.get_running_loop().set_exception_handler(lambda _, context: errors.append(context))
        net = await wire(Faults(delay=(1.0, 1.0)))
        net[1].send(2, b"too late")
        net[2].close()  # the receiver leaves before the datagram arrives
        await asyncio.sleep(2)
        return net, errors

    (transport, _, _, sink), errors = virtual(main)
    assert errors == []
    assert sink.arrivals == []
    assert transport.stats == stats(sent=1, delayed=1, lost=1)


def test_the_endpoint_and_transport_delegate_to_the_inner_ones() -> None:
    async def main() -> None:
        inner = MemoryTransport(max_datagram_size=1_000)
        transport = FaultyTransport(inner, Faults(loss=0.5))
        endpoint = await transport.open(1, RecordingSink())
        other = await inner.open(2, RecordingSink())
        assert (endpoint.robot_id, endpoint.max_datagram_size) == (1, 1_000)
        assert endpoint.address == ("memory", 1)
        assert list(endpoint.peers()) == [2]
        assert endpoint.knows(2)
        assert not endpoint.knows(3)
        assert transport.supports_virtual_time is True
        transport.authenticated = True  # as an authenticating wrapper outside would
        assert inner.authenticated is True
        assert transport.authenticated is True
        endpoint.close()
        assert not other.knows(1)  # the inner endpoint was closed too
        other.close()

    virtual(main)


def test_stats_is_a_copy() -> None:
    transport = FaultyTransport(MemoryTransport(), Faults())
    transport.stats["sent"] = 5
    assert transport.stats == stats()


async def test_a_wrapped_udp_transport_works_on_loopback() -> None:
    udp = UdpTransport()
    transport = FaultyTransport(udp, Faults(duplicate=1.0), seed=1)
    assert transport.supports_virtual_time is False
    sink = RecordingSink()
    sink.expect = 2
    receiver = await transport.open(2, sink)
    sender = await transport.open(1, RecordingSink())
    try:
        sender.send(2, b"over the wire")
        async with asyncio.timeout(5):  # a safety net only: loopback is immediate
            await sink.event.wait()
    finally:
        sender.close()
        receiver.close()
    assert [(data, who) for _, data, who in sink.arrivals] == [(b"over the wire", 1)] * 2
    assert transport.stats == stats(sent=1, duplicated=1)


# -- Faults ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        pytest.param({"loss": -0.1}, "loss", id="loss-negative"),
        pytest.param({"loss": 1.5}, "loss", id="loss-above-1"),
        pytest.param({"duplicate": math.nan}, "duplicate", id="duplicate-nan"),
        pytest.param({"reorder": True}, "reorder", id="reorder-bool"),
        pytest.param({"reorder": "0.1"}, "reorder", id="reorder-text"),
        pytest.param({"delay": (0.2, 0.1)}, "delay", id="delay-min-above-max"),
        pytest.param({"delay": (-1.0, 1.0)}, "delay", id="delay-negative"),
        pytest.param({"delay": (0.0, math.inf)}, "delay", id="delay-infinite"),
        pytest.param({"delay": (0.1,)}, "delay", id="delay-one-number"),
        pytest.param({"delay": 0.1}, "delay", id="delay-not-a-pair"),
    ],
)
def test_faults_refuse_invalid_values_naming_the_field(kwargs: dict[str, Any], field: str) -> None:
    with pytest.raises(ValueError, match=rf"^Faults\.{field} must"):
        Faults(**kwargs)


@pytest.mark.parametrize(
    ("faults", "expected"),
    [
        pytest.param(Faults(), False, id="none"),
        pytest.param(Faults(delay=(0.0, 0.0)), False, id="zero-delay"),
        pytest.param(Faults(loss=0.01), True, id="loss"),
        pytest.param(Faults(duplicate=0.01), True, id="duplicate"),
        pytest.param(Faults(reorder=0.01), True, id="reorder"),
        pytest.param(Faults(delay=(0.0, 0.1)), True, id="delay"),
    ],
)
def test_faults_any(faults: Faults, expected: bool) -> None:
    assert faults.any is expected


def test_faults_normalise_numbers() -> None:
    faults = Faults(loss=1, delay=[0, 2])  # type: ignore[arg-type]
    assert faults == Faults(loss=1.0, delay=(0.0, 2.0))
    assert isinstance(faults.delay, tuple)
    assert isinstance(faults.loss, float)


@pytest.mark.parametrize("hold", [-0.1, math.nan, math.inf])
def test_hold_must_be_finite_and_not_negative(hold: float) -> None:
    with pytest.raises(ValueError, match="hold must be"):
        FaultyTransport(MemoryTransport(), Faults(), hold=hold)
