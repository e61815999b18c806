"""MemoryTransport delivers in batches: in send order, never re-entrantly, losing nothing."""

from __future__ import annotations

import asyncio
from typing import Any

from cas_async import MemoryTransport
from cas_async.transport import Endpoint


class Sink:
    """Keeps what arrives; optionally answers or fails on some datagrams."""

    def __init__(self) -> None:
        self.received: list[tuple[bytes, int | None]] = []
        self.endpoint: Endpoint | None = None
        self.echo_to: int | None = None  # send b"echo:" + data there on each arrival
        self.fail_on: bytes | None = None

    def datagram_received(self, data: bytes, sender: int | None = None) -> None:
        self.received.append((data, sender))
        if data == self.fail_on:
            raise RuntimeError(f"sink refuses {data!r}")
        if self.echo_to is not None and not data.startswith(b"echo:"):
            self.send(self.echo_to, b"echo:" + data)

    def send(self, robot_id: int, data: bytes) -> None:
        assert self.endpoint is not None, "opened by _open()"
        self.endpoint.send(robot_id, data)

    def transport_dropped(self, reason: str, detail: str) -> None:
        raise AssertionError(f"nothing should be dropped: {reason} {detail}")

    def robot_joined(self, robot_id: int) -> None:
        """Membership news: not what these tests look at."""

    def robot_left(self, robot_id: int) -> None:
        """Membership news: not what these tests look at."""


async def _open(memory: MemoryTransport, robot_id: int) -> Sink:
    sink = Sink()
    sink.endpoint = await memory.open(robot_id, sink)
    return sink


async def _passes(count: int) -> None:
    for _ in range(count):
        await asyncio.sleep(0)


async def test_datagrams_of_several_senders_arrive_in_send_order_after_the_senders_yield() -> None:
    memory = MemoryTransport()
    receiver, one, two = [await _open(memory, rid) for rid in (1, 2, 3)]
    one.send(1, b"a1")
    two.send(1, b"b1")
    one.send(1, b"a2")
    assert receiver.received == []  # never delivered inside send()
    await _passes(1)
    assert receiver.received == [(b"a1", 2), (b"b1", 3), (b"a2", 2)]


async def test_what_a_receiver_sends_while_handling_a_batch_comes_in_a_later_batch() -> None:
    memory = MemoryTransport()
    receiver, sender = await _open(memory, 1), await _open(memory, 2)
    receiver.echo_to = 1  # a robot may send to itself through the transport
    for data in (b"x", b"y"):
        sender.send(1, data)
    await _passes(1)
    assert [data for data, _ in receiver.received] == [b"x", b"y"]  # not x, echo:x, y
    await _passes(1)
    assert [data for data, _ in receiver.received] == [b"x", b"y", b"echo:x", b"echo:y"]


async def test_a_sink_that_raises_loses_none_of_the_rest_of_its_batch() -> None:
    loop = asyncio.get_running_loop()
    reported: list[dict[str, Any]] = []
    loop.set_exception_handler(lambda _loop, context: reported.append(context))
    try:
        memory = MemoryTransport()
        receiver, sender = await _open(memory, 1), await _open(memory, 2)
        receiver.fail_on = b"bad"
        for data in (b"first", b"bad", b"last"):
            sender.send(1, data)
        await _passes(2)
    finally:
        loop.set_exception_handler(None)
    assert [data for data, _ in receiver.received] == [b"first", b"bad", b"last"]
    assert [type(c["exception"]) for c in reported] == [RuntimeError]
    assert "robot 1" in reported[0]["message"]


async def test_a_pass_of_sends_to_one_robot_schedules_one_delivery(
    monkeypatch: Any,
) -> None:
    loop = asyncio.get_running_loop()
    scheduled: list[object] = []
    call_soon = loop.call_soon

    def counting(callback: Any, *args: Any, **kwargs: Any) -> asyncio.Handle:
        scheduled.append(callback)
        return call_soon(callback, *args, **kwargs)

    memory = MemoryTransport()
    receiver, sender = await _open(memory, 1), await _open(memory, 2)
    monkeypatch.setattr(loop, "call_soon", counting)
    for n in range(100):
        sender.send(1, b"%d" % n)
    assert len(scheduled) == 1  # one per receiver and pass, not one per datagram
    monkeypatch.undo()
    await _passes(1)
    assert [data for data, _ in receiver.received] == [b"%d" % n for n in range(100)]
