"""Robot to robot against mango-agents 2.4: one-way messages/s under the same flow control.

Both sides carry the same payload (``Sample``'s six fields: 2 floats, an int, a bool,
a short str, 10 ints; mango gets them as a plain list, which it carries as content)
and use the same credit window: at most ``WINDOW`` (128) messages unacknowledged,
an ack carrying the count every ``ACK_EVERY`` (32) messages and for the last one.
Clock: first send to the arrival of the last ack, read by the sender. The receiving
side counts what it got; a run where that is not the total fails, so neither side
can win by losing messages.

``mango_one_process`` (target >= 2.0): in-process delivery on both sides, objects
passed. Framework: two robots on ``MemoryTransport(pass_objects=True)``. Mango:
two agents in the same container (mango hands the content object over without
encoding it either). ``mango_one_process_bytes`` (target >= 1.0) is the same
against a plain ``MemoryTransport``, which encodes and decodes every message as
over UDP. cas_async over UDP in one process is ``bench_external``'s
``external_throughput`` (same layers and window).

``mango_processes`` (target >= 3.0): two OS processes. Framework: robot 1 here,
robot 2 in a child over UDP (``bench_processes.framework_processes``). Mango: a TCP
container here with the sender and one in a child (``benchmarks._mango_peer``) with
the receiver; codec ``_mango_peer.CODEC`` (PROTOBUF: protobuf around pickle, mango's
fastest codec without optional extras, twice its default JSON here). Child start-up
is not timed; see ``bench_processes`` for the child's lifecycle.

mango's agents run their tasks unsuspendable (plain asyncio tasks), its cheapest
setting. mango is an optional extra (``pip install -e '.[bench]'``): without it this
module still imports, :func:`available` is false and :data:`BENCHES` is empty.
"""

from __future__ import annotations

import asyncio
import sys

from cas_async import MemoryTransport, Robot

from ._common import MESSAGES, Bench, OptionalPackage, main
from .bench_external import RECEIVER, SENDER, STALL
from .bench_processes import (
    FinalAckReceiver,
    GatedSender,
    framework_processes,
    peer_process,
)

__all__ = [
    "BENCHES",
    "available",
    "framework_pass_objects",
    "framework_memory",
    "mango_processes",
    "mango_same_container",
    "skip_message",
]

_PACKAGE = OptionalPackage.probe(
    "mango",
    "mango-agents",
    ("mango_one_process", "mango_one_process_bytes", "mango_processes"),
    extra="bench",
)


def available() -> bool:
    """Whether mango-agents can be imported, so the benches of this module can run."""
    return _PACKAGE.missing is None


def skip_message() -> str:
    """Why :data:`BENCHES` is empty, for the caller to print (empty when it is not)."""
    return _PACKAGE.skip_message()


def _check(what: str, received: int, total: int) -> None:
    if received != total:
        raise RuntimeError(f"{what}: the receiver got {received} of {total} messages")


async def framework_pass_objects(total: int) -> float:
    """Two robots on one ``MemoryTransport`` passing objects; returns messages/s."""
    return await framework_memory(total, pass_objects=True)


async def framework_memory(total: int, *, pass_objects: bool = False) -> float:
    """Two robots on one ``MemoryTransport``; returns messages/s."""
    loop = asyncio.get_running_loop()
    go: asyncio.Future[None] = loop.create_future()
    go.set_result(None)  # nothing to wait for: both robots are in this process
    done: asyncio.Future[float] = loop.create_future()
    memory = MemoryTransport(pass_objects=pass_objects)
    sender, receiver = GatedSender(total, go, done), FinalAckReceiver(total, loop.create_future())
    async with (
        Robot(RECEIVER, [receiver], transport=memory, messages=MESSAGES),
        Robot(SENDER, [sender], transport=memory, messages=MESSAGES),
    ):
        end = await asyncio.wait_for(done, STALL)
    _check("cas_async memory", receiver.count, total)
    return total / (end - sender.started)


async def mango_same_container(total: int) -> float:
    """Two mango agents in one container; returns messages/s."""
    from mango import activate  # type: ignore[import-untyped]

    from . import _mango_peer as mp

    done: asyncio.Future[float] = asyncio.get_running_loop().create_future()
    container = mp.tcp_container()
    receiver = container.register(mp.MangoReceiver(total), suggested_aid=mp.RECEIVER_AID)
    sender = container.register(mp.MangoSender(total, done))
    async with activate(container):
        sender.start(receiver.addr)
        end = await asyncio.wait_for(done, STALL)
    _check("mango same container", receiver.count, total)
    return total / (end - float(sender.started))


async def mango_processes(total: int) -> float:
    """A mango TCP container here sends to one in a child process; returns messages/s."""
    from mango import AgentAddress, activate

    from . import _mango_peer as mp

    done: asyncio.Future[float] = asyncio.get_running_loop().create_future()
    container = mp.tcp_container()
    sender = container.register(mp.MangoSender(total, done))
    async with (
        activate(container),
        peer_process("benchmarks._mango_peer", ["--total", str(total)]) as peer,
    ):
        sender.start(AgentAddress((container.addr[0], peer.port), mp.RECEIVER_AID))
        try:
            end = await asyncio.wait_for(done, STALL)
        except TimeoutError:
            raise RuntimeError(f"mango stalled: {sender.sent} sent, {sender.acked} acked") from None
        _check("mango TCP", await peer.finish(), total)
    return total / (end - float(sender.started))


def _benches() -> list[Bench]:
    if not available():
        return []
    return [
        Bench(
            name="mango_one_process",
            unit="msg/s",
            framework=framework_pass_objects,
            baseline=mango_same_container,
            size=100_000,
            quick_size=10_000,
            target=2.0,
        ),
        Bench(
            name="mango_one_process_bytes",
            unit="msg/s",
            framework=framework_memory,
            baseline=mango_same_container,
            size=100_000,
            quick_size=10_000,
            target=1.0,
        ),
        Bench(
            name="mango_processes",
            unit="msg/s",
            framework=framework_processes,
            baseline=mango_processes,
            size=50_000,
            quick_size=5_000,
            target=3.0,
        ),
    ]


BENCHES = _benches()

if __name__ == "__main__":
    if not BENCHES:
        print(skip_message(), file=sys.stderr)
        sys.exit(0)
    sys.exit(main(BENCHES))
