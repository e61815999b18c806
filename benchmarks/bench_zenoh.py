"""Robot to robot over Zenoh against UDP: throughput and round trip, one and two processes.

In these rows **"framework" is cas_async on ZenohTransport and "baseline" is cas_async
on UdpTransport**: the same robots, layers and messages, only the transport differs,
so the ratio is Zenoh / UDP (messages/s: higher is better; round trip: lower is
better). Every workload is an existing UDP benchmark, reused as the baseline as is:

``zenoh_throughput``: ``bench_external``'s ``external_throughput`` (one-way
``Sample`` messages, at most ``WINDOW`` = 128 unacknowledged, an ``Ack`` every
``ACK_EVERY`` = 32; clock from the first send to the last arrival). Baseline: its
framework side, two robots on one ``UdpTransport``. Zenoh: the same layers on two
robots with a ``ZenohTransport`` each (two sessions, one listening on loopback TCP,
the other connecting to it; robots of one transport would bypass Zenoh).

``zenoh_rtt``: ``external_rtt`` (median ``await self.request`` / ``self.reply``
round trip over ``WARMUP`` + N requests, the first ``WARMUP`` not counted). Same
pairs of transports as above.

``zenoh_processes``: ``bench_processes``' ``external_processes`` (the sender here,
the receiver in a child; clock from the first send to the ack of the last message).
Baseline: its framework side over UDP. Zenoh: the same layers, this process's
session listening, the child's (``benchmarks._zenoh_peer``) connecting to it.

``zenoh_processes_rtt``: ``external_rtt``'s asker here and its answerer in a child,
over UDP (:func:`udp_processes_rtt`, which no other module measures) and over Zenoh
(:func:`zenoh_processes_rtt`).

Zenoh robots learn of each other from liveliness tokens, asynchronously: each side
waits (at most ``KNOW_LIMIT`` seconds) until its layer ``knows`` the other before
anything is sent or timed; a UDP robot knows its peer from its directory at once.
Session start-up, child start-up and that wait are not timed. Each measurement uses
a fresh namespace and a fresh port (see :func:`listening`); every session is closed
when the measurement ends, also on errors, and every child is stopped and reaped
(``bench_processes.peer_process``). A child reports how many messages it received
or requests it answered; a run where that is not the total fails.

The targets are floors that flag a breakdown, not goals: Zenoh adds its own
threads (a Python callback thread per subscriber, Rust network threads) and a TCP
hop to every message, and on a 2-vCPU machine it reached 0.2-0.45 of UDP's
messages/s and 3-17 times its round trip (UDP robots' round trip in one process is
25-50 us, so the ratio swings with that denominator). Floors: throughput >= 0.1,
round trip <= 25. eclipse-zenoh is an optional extra (``pip install -e '.[zenoh]'``):
without it this module still imports, :func:`available` is false and
:data:`BENCHES` is empty.
"""

from __future__ import annotations

import asyncio
import itertools
import os
import socket
import statistics
import sys
from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager

from cas_async import ConfigurationError, Layer, Message, Robot, UdpTransport, ZenohTransport

from ._common import LOOPBACK, MESSAGES, Bench, OptionalPackage, main
from .bench_external import (
    RECEIVER,
    SENDER,
    STALL,
    WARMUP,
    Answerer,
    Asker,
    Receiver,
    framework_rtt,
    framework_throughput,
)
from .bench_processes import (
    GatedSender,
    bound_port,
    framework_processes,
    peer_process,
)

__all__ = [
    "BENCHES",
    "KNOW_LIMIT",
    "CountingAnswerer",
    "GatedAsker",
    "acquainted",
    "available",
    "listening",
    "skip_message",
    "udp_processes_rtt",
    "zenoh_processes",
    "zenoh_processes_rtt",
    "zenoh_rtt",
    "zenoh_throughput",
]

PEER = "benchmarks._zenoh_peer"
KNOW_LIMIT = 10.0  # seconds for two Zenoh robots to see each other's tokens
PORT_ATTEMPTS = 5  # a port picked free may be taken before the session listens on it
_namespaces = itertools.count()

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


def fresh_namespace() -> str:
    """A namespace no other measurement (of this process or another) uses."""
    return f"bench/p{os.getpid()}/n{next(_namespaces)}"


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind((LOOPBACK, 0))
        return int(sock.getsockname()[1])


@asynccontextmanager
async def listening(namespace: str) -> AsyncIterator[tuple[ZenohTransport, str]]:
    """A started ``ZenohTransport`` listening on loopback TCP, and its endpoint.

    The session is closed when the block ends, however it ends.

    Raises:
        ConfigurationError: no session could listen within ``PORT_ATTEMPTS`` ports.
    """
    for attempt in range(PORT_ATTEMPTS):
        endpoint = f"tcp/{LOOPBACK}:{_free_port()}"
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


async def udp_processes_rtt(rounds: int) -> float:
    """``external_rtt``'s asker here, its answerer in a child, over UDP; median us."""
    loop = asyncio.get_running_loop()
    go: asyncio.Future[None] = loop.create_future()
    done: asyncio.Future[list[float]] = loop.create_future()
    udp = UdpTransport(host=LOOPBACK)
    asker = GatedAsker(rounds, go, done)
    async with Robot(SENDER, [asker], transport=udp, messages=MESSAGES) as robot:
        args = ["udp-rtt", "--sender-port", str(bound_port(robot))]
        async with peer_process(PEER, args) as peer:
            udp.directory.add(RECEIVER, LOOPBACK, peer.port)
            go.set_result(None)
            latencies = await done
            _check("answered", await peer.finish(), WARMUP + rounds)
    return statistics.median(latencies) * 1e6


def _benches() -> list[Bench]:
    if not available():
        return []
    return [
        Bench(
            name="zenoh_throughput",
            unit="msg/s",
            framework=zenoh_throughput,
            baseline=framework_throughput,
            size=100_000,
            quick_size=10_000,
            target=0.1,
        ),
        Bench(
            name="zenoh_rtt",
            unit="us",
            framework=zenoh_rtt,
            baseline=framework_rtt,
            size=3_000,
            quick_size=500,
            target=25.0,
            higher_is_better=False,
        ),
        Bench(
            name="zenoh_processes",
            unit="msg/s",
            framework=zenoh_processes,
            baseline=framework_processes,
            size=100_000,
            quick_size=10_000,
            target=0.1,
        ),
        Bench(
            name="zenoh_processes_rtt",
            unit="us",
            framework=zenoh_processes_rtt,
            baseline=udp_processes_rtt,
            size=3_000,
            quick_size=500,
            target=25.0,
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
