"""Robot to robot over Zenoh against hand-written asyncio on raw Zenoh.

In these rows **"framework" is cas_async on ZenohTransport and "baseline" is raw
Zenoh** (``benchmarks._raw_zenoh``: two sessions, a publisher per direction with
``CongestionControl.BLOCK``, a callback subscriber handing payloads to the loop
through a deque with one wake-up per batch, msgpack of the framework's bytes). Both
sides move the same bytes over the same kind of link; the ratio is what cas_async
adds (messages/s: higher is better; round trip: lower is better).

``zenoh_throughput``: ``bench_external``'s ``external_throughput`` (one-way
``Sample`` messages, at most ``WINDOW`` = 128 unacknowledged, an ``Ack`` every
``ACK_EVERY`` = 32; clock from the first send to the last arrival) between two
robots with a ``ZenohTransport`` each (two sessions, one listening on loopback TCP,
the other connecting to it; robots of one transport would bypass Zenoh). Baseline:
the same window and acks on two raw sessions. Target >= 0.8.

``zenoh_rtt``: ``external_rtt`` (median ``await self.request`` / ``self.reply``
round trip over ``WARMUP`` + N requests, the first ``WARMUP`` not counted). Baseline:
the raw asker awaits a future its subscriber resolves; the raw answerer queues each
request for a task that publishes the reply. Target <= 1.5.

``zenoh_processes``: ``bench_processes``' ``external_processes`` (the sender here,
the receiver in a child, ``benchmarks._zenoh_peer``; clock from the first send to the
ack of the last message), this process's session listening, the child's connecting.
Baseline: the raw sender here, the raw receiver in the child. Target >= 0.8.

``zenoh_processes_rtt``: ``external_rtt``'s asker here and its answerer in a child.
Baseline: the raw asker here, the raw answerer in the child. Target <= 1.5.

These are issue 27's targets. Zenoh against UDP is no row of its own: in a run of
``python -m benchmarks`` it reads off the same run's ``external_*`` rows (raw Zenoh
against raw UDP, cas_async on Zenoh against cas_async on UDP).

Zenoh robots learn of each other from liveliness tokens, asynchronously: each side
waits (at most ``KNOW_LIMIT`` seconds) until its layer ``knows`` the other before
anything is sent or timed; the raw sides wait until each publisher matches the
other's subscriber (Zenoh drops a put that matches no subscriber it knows). Session
start-up, child start-up and that wait are not timed. Each measurement uses a fresh
namespace and a fresh port; every session is closed when the measurement ends, also
on errors, and every child is stopped and reaped (``bench_processes.peer_process``).
A child reports how many messages it received or requests it answered; a run where
that is not the total fails. eclipse-zenoh is an optional extra (``pip install -e
'.[zenoh]'``): without it this module still imports, :func:`available` is false and
:data:`BENCHES` is empty.
"""

from __future__ import annotations

import asyncio
import statistics
import sys
from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager

from cas_async import ConfigurationError, Layer, Message, Robot, ZenohTransport

from ._common import LOOPBACK, MESSAGES, Bench, OptionalPackage, main
from ._raw_zenoh import (
    KNOW_LIMIT,
    PORT_ATTEMPTS,
    RawAnswerer,
    RawAsker,
    RawReceiver,
    RawSender,
    free_port,
    fresh_namespace,
    matched,
    raw_listening,
    raw_session,
)
from .bench_external import (
    RECEIVER,
    SENDER,
    STALL,
    WARMUP,
    Answerer,
    Asker,
    Receiver,
)
from .bench_processes import GatedSender, peer_process

__all__ = [
    "BENCHES",
    "CountingAnswerer",
    "GatedAsker",
    "acquainted",
    "available",
    "connecting",
    "listening",
    "raw_processes",
    "raw_processes_rtt",
    "raw_rtt",
    "raw_throughput",
    "skip_message",
    "zenoh_processes",
    "zenoh_processes_rtt",
    "zenoh_rtt",
    "zenoh_throughput",
]

PEER = "benchmarks._zenoh_peer"

_PACKAGE = OptionalPackage.probe(
    "zenoh",
    "eclipse-zenoh",
    ("zenoh_throughput", "zenoh_rtt", "zenoh_processes", "zenoh_processes_rtt"),
    extra="zenoh",
)


def available() -> bool:
    """Whether eclipse-zenoh can be imported, so the benches of this module can run."""
    return _PACKAGE.missing is None


def skip_message() -> str:
    """Why :data:`BENCHES` is empty, for the caller to print (empty when it is not)."""
    return _PACKAGE.skip_message()


# -- helpers shared with the peer ---------------------------------------------------------


async def acquainted(*pairs: tuple[Layer, int]) -> None:
    """Waits until every ``(layer, robot)`` pair has ``layer.knows(robot)``.

    Raises:
        RuntimeError: not within ``KNOW_LIMIT`` seconds.
    """
    loop = asyncio.get_running_loop()
    deadline = loop.time() + KNOW_LIMIT
    while not all(layer.knows(robot) for layer, robot in pairs):
        if loop.time() > deadline:
            missing = [robot for layer, robot in pairs if not layer.knows(robot)]
            raise RuntimeError(f"Zenoh robots {missing} not seen within {KNOW_LIMIT} s")
        await asyncio.sleep(0.001)


@asynccontextmanager
async def listening(namespace: str) -> AsyncIterator[tuple[ZenohTransport, str]]:
    """A started ``ZenohTransport`` listening on loopback TCP, and its endpoint.

    The session is closed when the block ends, however it ends.

    Raises:
        ConfigurationError: no session could listen within ``PORT_ATTEMPTS`` ports.
    """
    for attempt in range(PORT_ATTEMPTS):
        endpoint = f"tcp/{LOOPBACK}:{free_port()}"
        transport = ZenohTransport(namespace=namespace, listen=[endpoint])
        try:
            await transport.start()
        except ConfigurationError:
            transport.close()
            if attempt == PORT_ATTEMPTS - 1:
                raise
            continue
        break
    try:
        yield transport, endpoint
    finally:
        transport.close()


def connecting(namespace: str, endpoint: str) -> ZenohTransport:
    """A ``ZenohTransport`` that listens nowhere and connects to ``endpoint``."""
    return ZenohTransport(namespace=namespace, listen=[], connect=[endpoint])


class GatedAsker(Asker):
    """bench_external's asker, held until ``go`` (the peer is not known yet)."""

    def __init__(
        self, rounds: int, go: asyncio.Future[None], done: asyncio.Future[list[float]]
    ) -> None:
        super().__init__(rounds, done)
        self.go = go

    async def inner_process(self) -> None:
        if not self.go.done():
            await self.go
        await super().inner_process()


class CountingAnswerer(Answerer):
    """bench_external's answerer, counting the requests it answered."""

    def __init__(self) -> None:
        self.count = 0

    async def handle_msg(self, msg: Message) -> None:
        self.count += 1
        await super().handle_msg(msg)


def _check(what: str, got: int, total: int) -> None:
    if got != total:
        raise RuntimeError(f"the peer {what} {got} of {total}")


def _zenoh_drops(*transports: ZenohTransport) -> str:
    return " ".join(f"{t.sent} sent, {t.received} received, drops {t.dropped};" for t in transports)


# -- one process ------------------------------------------------------------------------


async def zenoh_throughput(total: int) -> float:
    """``external_throughput`` between two robots on two Zenoh sessions; messages/s."""
    loop = asyncio.get_running_loop()
    go: asyncio.Future[None] = loop.create_future()
    done: asyncio.Future[float] = loop.create_future()
    sender = GatedSender(total, go, loop.create_future())  # timed to the last arrival
    receiver = Receiver(total, done)
    namespace = fresh_namespace()
    async with (
        listening(namespace) as (near, endpoint),
        connecting(namespace, endpoint) as far,
        Robot(RECEIVER, [receiver], transport=near, messages=MESSAGES) as r,
        Robot(SENDER, [sender], transport=far, messages=MESSAGES) as s,
    ):
        await acquainted((sender, RECEIVER), (receiver, SENDER))
        go.set_result(None)
        try:
            end = await asyncio.wait_for(done, STALL)
        except TimeoutError:
            raise RuntimeError(
                f"stalled at {receiver.count}/{total}; drops {r.dropped} {s.dropped}; "
                f"{_zenoh_drops(near, far)}"
            ) from None
    return total / (end - sender.started)


async def raw_throughput(total: int) -> float:
    """The same window and acks between two raw Zenoh sessions; messages/s."""
    namespace = fresh_namespace()
    async with raw_listening() as (near, endpoint), raw_session(endpoint) as far:
        receiver = RawReceiver(near, namespace, total, ack_last=False)
        sender = RawSender(far, namespace, total)
        await matched(sender.publisher, receiver.publisher)
        sender.top_up()
        try:
            end = await asyncio.wait_for(receiver.done, STALL)
        except TimeoutError:
            raise RuntimeError(f"raw Zenoh stalled at {receiver.count}/{total}") from None
    return total / (end - sender.started)


async def zenoh_rtt(rounds: int) -> float:
    """``external_rtt`` between two robots on two Zenoh sessions; median microseconds."""
    loop = asyncio.get_running_loop()
    go: asyncio.Future[None] = loop.create_future()
    done: asyncio.Future[list[float]] = loop.create_future()
    asker, answerer = GatedAsker(rounds, go, done), Answerer()
    namespace = fresh_namespace()
    async with (
        listening(namespace) as (near, endpoint),
        connecting(namespace, endpoint) as far,
        Robot(RECEIVER, [answerer], transport=near, messages=MESSAGES),
        Robot(SENDER, [asker], transport=far, messages=MESSAGES),
    ):
        await acquainted((asker, RECEIVER), (answerer, SENDER))
        go.set_result(None)
        latencies = await done
    return statistics.median(latencies) * 1e6


async def raw_rtt(rounds: int) -> float:
    """The raw asker and answerer on two raw Zenoh sessions; median microseconds."""
    namespace = fresh_namespace()
    async with raw_listening() as (near, endpoint), raw_session(endpoint) as far:
        answerer = RawAnswerer(near, namespace)
        try:
            asker = RawAsker(far, namespace)
            await matched(asker.publisher, answerer.publisher)
            latencies = await asker.latencies(WARMUP + rounds)
        finally:
            await answerer.stop()
    return statistics.median(latencies[WARMUP:]) * 1e6


# -- two processes ----------------------------------------------------------------------


async def zenoh_processes(total: int) -> float:
    """``external_processes`` with a Zenoh session on each side; messages/s."""
    loop = asyncio.get_running_loop()
    go: asyncio.Future[None] = loop.create_future()
    done: asyncio.Future[float] = loop.create_future()
    sender = GatedSender(total, go, done)
    namespace = fresh_namespace()
    args = ["zenoh-throughput", "--total", str(total), "--namespace", namespace]
    async with (
        listening(namespace) as (transport, endpoint),
        Robot(SENDER, [sender], transport=transport, messages=MESSAGES) as robot,
        peer_process(PEER, [*args, "--connect", endpoint]) as peer,
    ):
        await acquainted((sender, RECEIVER))  # the child knew robot 1 before "ready"
        go.set_result(None)
        try:
            end = await asyncio.wait_for(done, STALL)
        except TimeoutError:
            raise RuntimeError(
                f"stalled: {sender.sent} sent, {sender.acked} acked; drops {robot.dropped}; "
                f"{_zenoh_drops(transport)}"
            ) from None
        _check("received", await peer.finish(), total)
    return total / (end - sender.started)


async def raw_processes(total: int) -> float:
    """The raw sender here, the raw receiver in a child; messages/s."""
    namespace = fresh_namespace()
    args = ["raw-throughput", "--total", str(total), "--namespace", namespace]
    async with raw_listening() as (session, endpoint):
        sender = RawSender(session, namespace, total)
        async with peer_process(PEER, [*args, "--connect", endpoint]) as peer:
            await matched(sender.publisher)  # the child's publisher matched before "ready"
            sender.top_up()
            try:
                end = await asyncio.wait_for(sender.last_ack, STALL)
            except TimeoutError:
                raise RuntimeError(
                    f"raw Zenoh stalled: {sender.sent} sent, {sender.acked} acked"
                ) from None
            _check("received", await peer.finish(), total)
    return total / (end - sender.started)


async def zenoh_processes_rtt(rounds: int) -> float:
    """``external_rtt``'s asker here, its answerer in a child, over Zenoh; median us."""
    loop = asyncio.get_running_loop()
    go: asyncio.Future[None] = loop.create_future()
    done: asyncio.Future[list[float]] = loop.create_future()
    asker = GatedAsker(rounds, go, done)
    namespace = fresh_namespace()
    async with (
        listening(namespace) as (transport, endpoint),
        Robot(SENDER, [asker], transport=transport, messages=MESSAGES),
        peer_process(PEER, ["zenoh-rtt", "--namespace", namespace, "--connect", endpoint]) as peer,
    ):
        await acquainted((asker, RECEIVER))
        go.set_result(None)
        latencies = await done
        _check("answered", await peer.finish(), WARMUP + rounds)
    return statistics.median(latencies) * 1e6


async def raw_processes_rtt(rounds: int) -> float:
    """The raw asker here, the raw answerer in a child; median microseconds."""
    namespace = fresh_namespace()
    async with raw_listening() as (session, endpoint):
        asker = RawAsker(session, namespace)
        args = ["raw-rtt", "--namespace", namespace, "--connect", endpoint]
        async with peer_process(PEER, args) as peer:
            await matched(asker.publisher)
            latencies = await asker.latencies(WARMUP + rounds)
            _check("answered", await peer.finish(), WARMUP + rounds)
    return statistics.median(latencies[WARMUP:]) * 1e6


def _benches() -> list[Bench]:
    if not available():
        return []
    return [
        Bench(
            name="zenoh_throughput",
            unit="msg/s",
            framework=zenoh_throughput,
            baseline=raw_throughput,
            size=100_000,
            quick_size=10_000,
            target=0.8,
        ),
        Bench(
            name="zenoh_rtt",
            unit="us",
            framework=zenoh_rtt,
            baseline=raw_rtt,
            size=3_000,
            quick_size=500,
            target=1.5,
            higher_is_better=False,
        ),
        Bench(
            name="zenoh_processes",
            unit="msg/s",
            framework=zenoh_processes,
            baseline=raw_processes,
            size=100_000,
            quick_size=10_000,
            target=0.8,
        ),
        Bench(
            name="zenoh_processes_rtt",
            unit="us",
            framework=zenoh_processes_rtt,
            baseline=raw_processes_rtt,
            size=3_000,
            quick_size=500,
            target=1.5,
            higher_is_better=False,
        ),
    ]


BENCHES = _benches()


def run(argv: Sequence[str] | None = None) -> int:
    """``python -m benchmarks.bench_zenoh``: these benches, or a skip message without zenoh."""
    if not BENCHES:
        print(skip_message(), file=sys.stderr)
        return 0
    return main(BENCHES, argv)


if __name__ == "__main__":
    sys.exit(run())
