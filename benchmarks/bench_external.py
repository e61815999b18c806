"""External messages between two robots over UDP on 127.0.0.1, in one process.

(a) ``external_throughput``: one-way messages/s. Framework: robot 1's layer sends
``Sample`` messages with ``self.send``; robot 2's layer counts them in
``handle_msg`` and every ``ACK_EVERY`` messages answers with an ``Ack`` external
message; the sender keeps at most ``WINDOW`` messages unacknowledged, topping up
in ``inner_process`` after each batch of acks. Baseline: two raw
``asyncio.DatagramProtocol`` endpoints with ``msgpack.packb``/``unpackb`` of the
same header and fields, the same credit window and acks, and the same socket
buffers, all done in the protocol callbacks. Clock: first send to last arrival.
Target: framework / baseline >= 0.8.

(b) ``external_rtt``: median request/reply round trip. Framework: ``await
self.request(2, sample)``, answered by robot 2 with ``self.reply`` from
``handle_msg``. Baseline: the asking coroutine sends and awaits a future that its
protocol resolves; the answering protocol puts each decoded request on an
``asyncio.Queue`` read by a task that sends the reply (datagram -> queue -> task,
as in LIMITS.md, because the framework answers from a task too).
Target: framework / baseline <= 1.25.
"""

from __future__ import annotations

import asyncio
import socket
import statistics
import sys
import time
from typing import Any

from cas_async import Layer, Message, Robot, UdpTransport

from ._common import (
    COUNT_AT,
    ID_AT,
    LOOPBACK,
    MESSAGES,
    N_AT,
    SOCKET_BUFFER,
    Ack,
    Bench,
    main,
    raw_ack,
    raw_pack,
    raw_sample,
    raw_unpack,
    sample,
)

WINDOW = 128  # unacknowledged messages at most
ACK_EVERY = 32
WARMUP = 200  # round trips not measured
STALL = 20.0  # seconds without completion: datagrams were lost
SENDER, RECEIVER = 1, 2


# -- (a) throughput, framework ----------------------------------------------------------


class Sender(Layer):
    def __init__(self, total: int) -> None:
        self.total = total
        self.sent = 0
        self.acked = 0
        self.started = 0.0

    async def inner_process(self) -> None:
        if not self.started:
            self.started = time.perf_counter()
        n, limit = self.sent, min(self.total, self.acked + WINDOW)
        while n < limit:
            self.send(RECEIVER, sample(n))
            n += 1
        self.sent = n

    async def handle_msg(self, msg: Message) -> None:
        assert isinstance(msg, Ack)
        self.acked = msg.count


class Receiver(Layer):
    def __init__(self, total: int, done: asyncio.Future[float]) -> None:
        self.total = total
        self.done = done
        self.count = 0

    async def handle_msg(self, msg: Message) -> None:
        self.count = count = self.count + 1
        if count % ACK_EVERY == 0:
            self.send(SENDER, Ack(count))
        if count == self.total:
            self.done.set_result(time.perf_counter())


async def framework_throughput(total: int) -> float:
    done: asyncio.Future[float] = asyncio.get_running_loop().create_future()
    udp = UdpTransport(host=LOOPBACK)
    sender, receiver = Sender(total), Receiver(total, done)
    async with (
        Robot(RECEIVER, [receiver], transport=udp, messages=MESSAGES) as r,
        Robot(SENDER, [sender], transport=udp, messages=MESSAGES) as s,
    ):
        try:
            end = await asyncio.wait_for(done, STALL)
        except TimeoutError:
            raise RuntimeError(
                f"stalled at {receiver.count}/{total}; drops {r.dropped} {s.dropped}"
            ) from None
    return total / (end - sender.started)


# -- (a) throughput, baseline -------------------------------------------------------------


async def open_raw(protocol: asyncio.DatagramProtocol) -> asyncio.DatagramTransport:
    loop = asyncio.get_running_loop()
    transport, _ = await loop.create_datagram_endpoint(lambda: protocol, local_addr=(LOOPBACK, 0))
    sock = transport.get_extra_info("socket")
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SOCKET_BUFFER)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SOCKET_BUFFER)
    return transport


class RawSender(asyncio.DatagramProtocol):
    def __init__(self, total: int) -> None:
        self.total = total
        self.sent = 0
        self.acked = 0
        self.transport: Any = None
        self.peer: Any = None

    def top_up(self) -> None:
        n, limit = self.sent, min(self.total, self.acked + WINDOW)
        sendto, peer = self.transport.sendto, self.peer
        while n < limit:
            sendto(raw_pack(raw_sample(n, SENDER)), peer)
            n += 1
        self.sent = n

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.acked = raw_unpack(data)[COUNT_AT]  # type: ignore[assignment]
        self.top_up()


class RawReceiver(asyncio.DatagramProtocol):
    def __init__(self, total: int, done: asyncio.Future[float]) -> None:
        self.total = total
        self.done = done
        self.count = 0
        self.transport: Any = None

    def datagram_received(self, data: bytes, addr: Any) -> None:
        raw_unpack(data)
        self.count = count = self.count + 1
        if count % ACK_EVERY == 0:
            self.transport.sendto(raw_pack(raw_ack(count, RECEIVER)), addr)
        if count == self.total:
            self.done.set_result(time.perf_counter())


async def baseline_throughput(total: int) -> float:
    done: asyncio.Future[float] = asyncio.get_running_loop().create_future()
    sender, receiver = RawSender(total), RawReceiver(total, done)
    receiver.transport = await open_raw(receiver)
    try:
        sender.transport = await open_raw(sender)
        try:
            sender.peer = receiver.transport.get_extra_info("sockname")
            started = time.perf_counter()
            sender.top_up()
            try:
                end = await asyncio.wait_for(done, STALL)
            except TimeoutError:
                raise RuntimeError(f"stalled at {receiver.count}/{total}") from None
        finally:
            sender.transport.close()
    finally:
        receiver.transport.close()
    return total / (end - started)


# -- (b) round trip, framework ------------------------------------------------------------


class Asker(Layer):
    def __init__(self, rounds: int, done: asyncio.Future[list[float]]) -> None:
        self.rounds = rounds
        self.done = done
        self.started = False

    async def inner_process(self) -> None:
        if self.started:
            return
        self.started = True
        latencies = []
        try:
            for n in range(WARMUP + self.rounds):
                t = time.perf_counter()
                await self.request(RECEIVER, sample(n), timeout=5.0)
                latencies.append(time.perf_counter() - t)
        except Exception as exc:
            self.done.set_exception(exc)
        else:
            self.done.set_result(latencies[WARMUP:])


class Answerer(Layer):
    async def handle_msg(self, msg: Message) -> None:
        self.reply(msg, sample(msg.n))  # type: ignore[attr-defined]


async def framework_rtt(rounds: int) -> float:
    done: asyncio.Future[list[float]] = asyncio.get_running_loop().create_future()
    udp = UdpTransport(host=LOOPBACK)
    async with (
        Robot(RECEIVER, [Answerer()], transport=udp, messages=MESSAGES),
        Robot(SENDER, [Asker(rounds, done)], transport=udp, messages=MESSAGES),
    ):
        latencies = await done
    return statistics.median(latencies) * 1e6


# -- (b) round trip, baseline -------------------------------------------------------------


class RawAsker(asyncio.DatagramProtocol):
    waiter: asyncio.Future[Any] | None = None

    def datagram_received(self, data: bytes, addr: Any) -> None:
        reply = raw_unpack(data)
        waiter, self.waiter = self.waiter, None
        if waiter is not None and not waiter.done():
            waiter.set_result(reply)


class RawAnswerer(asyncio.DatagramProtocol):
    def __init__(self) -> None:
        self.inbox: asyncio.Queue[tuple[list[Any], Any]] = asyncio.Queue()

    def datagram_received(self, data: bytes, addr: Any) -> None:
        self.inbox.put_nowait((raw_unpack(data), addr))


async def answer(transport: asyncio.DatagramTransport, inbox: asyncio.Queue[Any]) -> None:
    while True:
        request, addr = await inbox.get()
        transport.sendto(raw_pack(raw_sample(request[N_AT], RECEIVER, request[ID_AT])), addr)


async def baseline_rtt(rounds: int) -> float:
    loop = asyncio.get_running_loop()
    asker, answerer = RawAsker(), RawAnswerer()
    answer_transport = await open_raw(answerer)
    answering = asyncio.create_task(answer(answer_transport, answerer.inbox))
    ask_transport = await open_raw(asker)
    try:
        peer = answer_transport.get_extra_info("sockname")
        latencies = []
        for n in range(WARMUP + rounds):
            t = time.perf_counter()
            waiter = asker.waiter = loop.create_future()
            ask_transport.sendto(raw_pack(raw_sample(n, SENDER)), peer)
            await waiter
            latencies.append(time.perf_counter() - t)
    finally:
        answering.cancel()
        await asyncio.gather(answering, return_exceptions=True)
        ask_transport.close()
        answer_transport.close()
    return statistics.median(latencies[WARMUP:]) * 1e6


BENCHES = [
    Bench(
        name="external_throughput",
        unit="msg/s",
        framework=framework_throughput,
        baseline=baseline_throughput,
        size=100_000,
        quick_size=10_000,
        target=0.8,
    ),
    Bench(
        name="external_rtt",
        unit="us",
        framework=framework_rtt,
        baseline=baseline_rtt,
        size=3_000,
        quick_size=500,
        target=1.25,
        higher_is_better=False,
    ),
]

if __name__ == "__main__":
    sys.exit(main(BENCHES))
