"""The receiving process of ``bench_processes`` (and of ``bench_mango``'s framework side).

Usage::

    python -m benchmarks._process_peer framework --total N --sender-port P --loop L --deadline S
    python -m benchmarks._process_peer raw --total N --loop L --deadline S

``framework``: robot 2 (:class:`~benchmarks.bench_processes.FinalAckReceiver`) on a
``UdpTransport`` that knows robot 1 at ``127.0.0.1:P``. ``raw``: a
``DatagramProtocol`` answering ``raw_ack`` to whoever sent. Both acknowledge every
``ACK_EVERY`` messages and the last one.

Protocol with the parent: prints ``ready PORT`` once listening; runs until its stdin
closes (the parent is done, or died); then prints ``received COUNT`` and exits 0.
Exits 2 without waiting further after ``--deadline`` seconds.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from collections.abc import Sequence
from typing import Any

import cas_async
from cas_async import Robot, UdpDirectory, UdpTransport

from ._common import LOOPBACK, MESSAGES, pin_malloc, raw_ack, raw_pack
from .bench_external import ACK_EVERY, RECEIVER, SENDER, RawReceiver, open_raw
from .bench_processes import FinalAckReceiver, bound_port

__all__ = ["main", "stdin_closed"]


class _RawReceiver(RawReceiver):
    def datagram_received(self, data: bytes, addr: Any) -> None:
        super().datagram_received(data, addr)
        if self.count == self.total and self.total % ACK_EVERY:
            self.transport.sendto(raw_pack(raw_ack(self.count, RECEIVER)), addr)


async def stdin_closed() -> None:
    """Returns when this process's stdin reaches end of file (the parent's stop signal)."""
    reader = asyncio.StreamReader()
    loop = asyncio.get_running_loop()
    pipe, _ = await loop.connect_read_pipe(lambda: asyncio.StreamReaderProtocol(reader), sys.stdin)
    try:
        await reader.read()
    finally:
        pipe.close()


async def _framework(total: int, sender_port: int, deadline: float) -> int:
    done: asyncio.Future[float] = asyncio.get_running_loop().create_future()
    transport = UdpTransport(UdpDirectory({SENDER: (LOOPBACK, sender_port)}))
    receiver = FinalAckReceiver(total, done)
    async with Robot(RECEIVER, [receiver], transport=transport, messages=MESSAGES) as robot:
        print(f"ready {bound_port(robot)}", flush=True)
        await asyncio.wait_for(stdin_closed(), deadline)
    return receiver.count


async def _raw(total: int, deadline: float) -> int:
    done: asyncio.Future[float] = asyncio.get_running_loop().create_future()
    protocol = _RawReceiver(total, done)
    protocol.transport = transport = await open_raw(protocol)
    try:
        print(f"ready {transport.get_extra_info('sockname')[1]}", flush=True)
        await asyncio.wait_for(stdin_closed(), deadline)
    finally:
        transport.close()
    return protocol.count


async def _serve(args: argparse.Namespace) -> int:
    try:
        if args.mode == "framework":
            count = await _framework(args.total, args.sender_port, args.deadline)
        else:
            count = await _raw(args.total, args.deadline)
    except TimeoutError:
        print(f"_process_peer: no stop signal within {args.deadline} s: exiting", file=sys.stderr)
        return 2
    print(f"received {count}", flush=True)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Parses the arguments, receives until told to stop, returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks._process_peer")
    parser.add_argument("mode", choices=["framework", "raw"])
    parser.add_argument("--total", type=int, required=True)
    parser.add_argument("--sender-port", type=int, default=0)
    parser.add_argument("--loop", choices=["stdlib", "uvloop"], default="stdlib")
    parser.add_argument("--deadline", type=float, default=120.0)
    args = parser.parse_args(argv)
    pin_malloc()  # as the parent does by default: the same allocation pattern in every run
    return cas_async.run(_serve(args), use_uvloop=args.loop == "uvloop")


if __name__ == "__main__":
    sys.exit(main())
