"""External one-way messages between two OS processes over UDP on 127.0.0.1.

``external_processes``: messages/s from a sender in this process to a receiver in a
child process (``python -m benchmarks._process_peer``), with the flow control of
``bench_external``'s throughput benchmark: at most ``WINDOW`` messages
unacknowledged, an ``Ack`` every ``ACK_EVERY`` messages, plus one for the last
message when the total is not a multiple of ``ACK_EVERY``.

Framework: robot 1 here sends ``Sample`` messages with ``self.send``; robot 2 in
the child counts them and acknowledges. Baseline: a raw ``asyncio.DatagramProtocol``
with ``msgpack`` on both sides, the same header and fields (``raw_sample`` /
``raw_ack``), the same window, acks and ``SO_RCVBUF`` / ``SO_SNDBUF``. The child
runs on the same loop as this process (stdlib or uvloop) and always pins malloc
(see ``pin_malloc``).

Clock: from the first send to the arrival of the ack of the last message, both read
by the sender. The two processes have no common clock, but the acks bring the end
back to the sender, so one clock times it all; the figure includes one ack's
one-way trip more than the pure arrival time (tens of microseconds against the
hundreds of milliseconds of a run). Starting the child, its imports and the
handshake happen before the first send and are not timed. The child reports how
many messages it received; a run where that is not the total fails.

Child lifecycle (:func:`peer_process`): the child prints ``ready PORT`` once it
listens, runs until its stdin closes, then prints ``received COUNT`` and exits. The
parent closes stdin when done, kills the child on any error or timeout, and always
waits for it. The child also exits on its own when its stdin closes because the
parent died, or after a deadline: no orphan outlives a run.

Target: framework / baseline >= 0.8.
"""

from __future__ import annotations

import asyncio
import os
import sys
import time
from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from cas_async import Message, Robot, UdpTransport

from ._common import LOOPBACK, MESSAGES, WAIT_LIMIT, Ack, Bench, main
from .bench_external import (
    ACK_EVERY,
    RECEIVER,
    SENDER,
    STALL,
    RawSender,
    Receiver,
    Sender,
    open_raw,
)

__all__ = [
    "BENCHES",
    "FinalAckReceiver",
    "GatedSender",
    "Peer",
    "baseline_processes",
    "bound_port",
    "framework_processes",
    "loop_name",
    "peer_process",
]

ROOT = Path(__file__).resolve().parent.parent
START_LIMIT = 30.0  # seconds for a child to print its ready line
STOP_LIMIT = 10.0  # seconds for a child to report and exit once its stdin is closed
PEER_DEADLINE = WAIT_LIMIT + START_LIMIT  # a child gives up by itself after this


def loop_name() -> str:
    """``"uvloop"`` or ``"stdlib"``: the running loop, for the child to use the same."""
    return (
        "uvloop" if type(asyncio.get_running_loop()).__module__.startswith("uvloop") else "stdlib"
    )


# -- layers shared with the peer and bench_mango -------------------------------------------


class GatedSender(Sender):
    """bench_external's sender, held until ``go`` and resolving ``done`` on the last ack."""

    def __init__(self, total: int, go: asyncio.Future[None], done: asyncio.Future[float]) -> None:
        super().__init__(total)
        self.go = go
        self.done = done

    async def inner_process(self) -> None:
        if not self.go.done():
            await self.go  # the peer is not listening yet: nothing must be sent or timed
        await super().inner_process()

    async def handle_msg(self, msg: Message) -> None:
        await super().handle_msg(msg)
        if self.acked >= self.total and not self.done.done():
            self.done.set_result(time.perf_counter())


class FinalAckReceiver(Receiver):
    """bench_external's receiver, also acknowledging the last message (total % 32 != 0)."""

    async def handle_msg(self, msg: Message) -> None:
        await super().handle_msg(msg)
        if self.count == self.total and self.total % ACK_EVERY:
            self.send(SENDER, Ack(self.count))


class _RawSender(RawSender):
    def __init__(self, total: int, done: asyncio.Future[float]) -> None:
        super().__init__(total)
        self.done = done

    def datagram_received(self, data: bytes, addr: Any) -> None:
        super().datagram_received(data, addr)
        if self.acked >= self.total and not self.done.done():
            self.done.set_result(time.perf_counter())


# -- the child process ----------------------------------------------------------------------


async def _collect(process: asyncio.subprocess.Process) -> bytes:
    """Closes the child's stdin (its signal to stop), reads its stdout to the end, reaps it."""
    assert process.stdin is not None
    process.stdin.close()
    out, _ = await process.communicate()
    return out


@dataclass(frozen=True)
class Peer:
    """A started child: the UDP or TCP port it listens on, and its process."""

    port: int
    process: asyncio.subprocess.Process

    async def finish(self) -> int:
        """Closes the child's stdin and returns the count it reports before exiting.

        Raises:
            RuntimeError: the child exited with an error or reported no count.
            TimeoutError: the child did not exit within ``STOP_LIMIT`` seconds.
        """
        out = await asyncio.wait_for(_collect(self.process), STOP_LIMIT)
        lines = out.decode().split()
        if self.process.returncode != 0 or lines[:1] != ["received"]:
            raise RuntimeError(
                f"peer exited with {self.process.returncode} and printed {out.decode()!r}"
            )
        return int(lines[1])


@asynccontextmanager
async def peer_process(module: str, args: Sequence[str]) -> AsyncIterator[Peer]:
    """Runs ``python -m module *args --loop L --deadline S`` until the block ends.

    Yields once the child printed ``ready PORT``. On leaving the block normally the
    child is told to stop (its stdin closed) unless :meth:`Peer.finish` did so; on
    an error or cancellation it is killed. Either way it has exited afterwards.

    Raises:
        RuntimeError: the child exited or printed something else before its ready line.
        TimeoutError: no ready line within ``START_LIMIT`` seconds.
    """
    python_path = [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(python_path)}
    command = [*args, "--loop", loop_name(), "--deadline", str(PEER_DEADLINE)]
    process = await asyncio.create_subprocess_exec(
        *[sys.executable, "-m", module, *command],
        cwd=ROOT,
        env=env,
        stdin=asyncio.subprocess.PIPE,  # closing it tells the child to stop
        stdout=asyncio.subprocess.PIPE,  # stderr is ours: the child's errors show
    )
    try:
        assert process.stdout is not None
        line = (await asyncio.wait_for(process.stdout.readline(), START_LIMIT)).decode()
        if not line.startswith("ready "):
            raise RuntimeError(
                f"peer {module} did not start: it printed {line!r} (its stderr is above)"
            )
        yield Peer(int(line.split()[1]), process)
        if process.returncode is None:
            await asyncio.wait_for(_collect(process), STOP_LIMIT)
    finally:
        if process.returncode is None:  # an error, a timeout or a cancellation: no waiting
            process.kill()
            await _collect(process)


# -- the two sides ----------------------------------------------------------------------


def bound_port(robot: Robot) -> int:
    """The UDP port a robot bound (its address is ``(host, port)`` on ``UdpTransport``)."""
    address = robot.address
    assert isinstance(address, tuple), address
    return int(address[1])


def _check(received: int, total: int) -> None:
    if received != total:
        raise RuntimeError(f"the peer received {received} of {total} messages")


async def framework_processes(total: int) -> float:
    """Robot 1 here sends ``total`` samples to robot 2 in a child; returns messages/s."""
    loop = asyncio.get_running_loop()
    go: asyncio.Future[None] = loop.create_future()
    done: asyncio.Future[float] = loop.create_future()
    udp = UdpTransport(host=LOOPBACK)
    sender = GatedSender(total, go, done)
    async with Robot(SENDER, [sender], transport=udp, messages=MESSAGES) as robot:
        port = bound_port(robot)
        args = ["framework", "--total", str(total), "--sender-port", str(port)]
        async with peer_process("benchmarks._process_peer", args) as peer:
            udp.directory.add(RECEIVER, LOOPBACK, peer.port)
            go.set_result(None)
            try:
                end = await asyncio.wait_for(done, STALL)
            except TimeoutError:
                raise RuntimeError(
                    f"stalled: {sender.sent} sent, {sender.acked} acked; drops {robot.dropped}"
                ) from None
            _check(await peer.finish(), total)
    return total / (end - sender.started)


async def baseline_processes(total: int) -> float:
    """Raw ``DatagramProtocol`` + msgpack on both sides; returns messages/s."""
    done: asyncio.Future[float] = asyncio.get_running_loop().create_future()
    sender = _RawSender(total, done)
    sender.transport = await open_raw(sender)
    try:
        async with peer_process("benchmarks._process_peer", ["raw", "--total", str(total)]) as peer:
            sender.peer = (LOOPBACK, peer.port)
            started = time.perf_counter()
            sender.top_up()
            try:
                end = await asyncio.wait_for(done, STALL)
            except TimeoutError:
                raise RuntimeError(f"stalled: {sender.sent} sent, {sender.acked} acked") from None
            _check(await peer.finish(), total)
    finally:
        sender.transport.close()
    return total / (end - started)


BENCHES = [
    Bench(
        name="external_processes",
        unit="msg/s",
        framework=framework_processes,
        baseline=baseline_processes,
        size=100_000,
        quick_size=10_000,
        target=0.8,
    ),
]

if __name__ == "__main__":
    sys.exit(main(BENCHES))
