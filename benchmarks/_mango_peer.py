"""The mango-agents side of ``bench_mango``: two agents, and the receiving process.

Imports mango: ``bench_mango`` imports this module only when mango is importable.

:class:`MangoSender` keeps at most ``WINDOW`` samples unacknowledged: one task
(scheduled by the agent, not suspendable) sends while it has credit and waits on an
``asyncio.Event`` that each ack sets. :class:`MangoReceiver` counts the samples and
answers every ``ACK_EVERY``-th one, and the last, with the count (mango's idiom for
sending from the synchronous ``handle_message``: ``schedule_instant_message``).

Usage as the receiving process::

    python -m benchmarks._mango_peer --total N --loop L --deadline S

It runs a TCP container (port chosen by the OS, codec :data:`CODEC`) holding the
receiver as ``"receiver"``, prints ``ready PORT``, runs until its stdin closes,
prints ``received COUNT`` and exits 0; it exits 2 after ``--deadline`` seconds.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
import time
from collections.abc import Sequence
from typing import Any

# mango ships no type information: its names are Any here.
from mango import (  # type: ignore[import-untyped]
    PROTOBUF,
    Agent,
    AgentAddress,
    AsyncioClock,
    activate,
    sender_addr,
)
from mango.container.core import Container  # type: ignore[import-untyped]
from mango.container.protocol import ContainerProtocol  # type: ignore[import-untyped]
from mango.container.tcp import TCPContainer  # type: ignore[import-untyped]

import cas_async

from ._common import LOOPBACK, VALUES, pin_malloc
from ._process_peer import stdin_closed
from .bench_external import ACK_EVERY, WINDOW

__all__ = ["CODEC", "RECEIVER_AID", "MangoReceiver", "MangoSender", "main", "tcp_container"]

# mango's fastest codec that needs nothing beyond mango-agents itself: protobuf around
# pickled content and meta, about twice the speed of its default JSON codec for this
# payload (FastJSON needs the optional msgspec). It unpickles what arrives: unsafe on
# a real network, acceptable between two local processes of one benchmark.
CODEC = PROTOBUF
RECEIVER_AID = "receiver"


class _TCPContainer(TCPContainer):  # type: ignore[misc]
    """mango's TCP container, startable on uvloop too.

    mango 2.4's ``TCPContainer.start`` reads the bound port as
    ``server.sockets[0]._sock.getsockname()``; uvloop's socket objects have no
    ``_sock`` (AttributeError), so mango cannot start a TCP container on uvloop at all.
    This ``start`` is mango's with the public ``getsockname()`` instead; nothing else
    differs.
    """

    async def start(self) -> None:
        self.server = await asyncio.get_running_loop().create_server(
            lambda: ContainerProtocol(container=self, codec=self.codec), *self.addr
        )
        self.addr: tuple[str, int] = (self.addr[0], self.server.sockets[0].getsockname()[1])
        await Container.start(self)


def tcp_container() -> Container:
    """A TCP container on 127.0.0.1, port chosen by the OS when it starts.

    What ``mango.create_tcp_container((LOOPBACK, 0), codec=CODEC())`` builds, but
    startable on uvloop (see :class:`_TCPContainer`).
    """
    return _TCPContainer(addr=(LOOPBACK, 0), codec=CODEC(), clock=AsyncioClock())


class MangoSender(Agent):  # type: ignore[misc]
    """Sends ``total`` samples to ``peer`` under the credit window; ``done`` gets the end time."""

    def __init__(self, total: int, done: asyncio.Future[float]) -> None:
        super().__init__()
        self.total = total
        self.done = done
        self.sent = 0
        self.acked = 0
        self.started = 0.0
        self.credit = asyncio.Event()

    def on_register(self) -> None:
        # Plain asyncio tasks: mango's default wraps every await in a Python-level
        # Suspendable, a cost these agents do not need (the benchmark favours mango).
        self.suspendable_tasks = False

    def start(self, peer: AgentAddress) -> None:
        """Starts sending; the clock starts with the first send."""
        self.schedule_instant_task(self._pump(peer))

    async def _pump(self, peer: AgentAddress) -> None:
        self.started = time.perf_counter()
        while self.sent < self.total:
            if self.sent >= self.acked + WINDOW:
                # No await between the check and the wait: an ack cannot slip in between.
                self.credit.clear()
                await self.credit.wait()
                continue
            await self.send_message([1.5, -2.25, self.sent, True, "robot-7", VALUES], peer)
            self.sent += 1

    def handle_message(self, content: Any, meta: dict[str, Any]) -> None:
        self.acked = content
        self.credit.set()
        if content >= self.total and not self.done.done():
            self.done.set_result(time.perf_counter())


class MangoReceiver(Agent):  # type: ignore[misc]
    """Counts samples; acknowledges every ``ACK_EVERY``-th and the last with the count."""

    def __init__(self, total: int) -> None:
        super().__init__()
        self.total = total
        self.count = 0

    def on_register(self) -> None:
        self.suspendable_tasks = False

    def handle_message(self, content: Any, meta: dict[str, Any]) -> None:
        self.count = count = self.count + 1
        if count % ACK_EVERY == 0 or count == self.total:
            self.schedule_instant_message(count, sender_addr(meta))


async def _serve(total: int, deadline: float) -> int:
    container = tcp_container()
    receiver = container.register(MangoReceiver(total), suggested_aid=RECEIVER_AID)
    try:
        async with activate(container):
            print(f"ready {container.addr[1]}", flush=True)
            await asyncio.wait_for(stdin_closed(), deadline)
    except TimeoutError:
        print(f"_mango_peer: no stop signal within {deadline} s: exiting", file=sys.stderr)
        return 2
    print(f"received {receiver.count}", flush=True)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Parses the arguments, receives until told to stop, returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks._mango_peer")
    parser.add_argument("--total", type=int, required=True)
    parser.add_argument("--loop", choices=["stdlib", "uvloop"], default="stdlib")
    parser.add_argument("--deadline", type=float, default=120.0)
    args = parser.parse_args(argv)
    pin_malloc()
    return cas_async.run(_serve(args.total, args.deadline), use_uvloop=args.loop == "uvloop")


if __name__ == "__main__":
    sys.exit(main())
