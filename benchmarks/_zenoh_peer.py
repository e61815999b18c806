"""The child process of ``bench_zenoh``: robot 2 over Zenoh, or its raw Zenoh baseline.

Usage::

    python -m benchmarks._zenoh_peer MODE --namespace NS --connect E [--total N] \
        --loop L --deadline S

``zenoh-throughput``: robot 2 (:class:`~benchmarks.bench_processes.FinalAckReceiver`)
on a ``ZenohTransport`` connecting to endpoint ``E`` (the parent's session), under
namespace ``NS``. ``zenoh-rtt``: robot 2 answering requests
(:class:`~benchmarks.bench_zenoh.CountingAnswerer`) on the same. ``raw-throughput``
and ``raw-rtt``: their hand-written counterparts on a raw Zenoh session
(:class:`~benchmarks._raw_zenoh.RawReceiver` acknowledging the last message too,
:class:`~benchmarks._raw_zenoh.RawAnswerer`).

Protocol with the parent (``bench_processes.peer_process``): prints ``ready 0`` once
robot 2 can reach robot 1 (it knows robot 1's token; raw: its publisher matches the
parent's subscriber); runs until its stdin closes (the parent is done, or died); then
prints ``received COUNT`` (messages received, or requests answered) and exits 0.
Exits 2 without waiting further after ``--deadline`` seconds, and 1 when the parent is
not seen within ``KNOW_LIMIT``. The Zenoh session is closed on every way out: a
process with an open Zenoh subscriber does not exit.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from collections.abc import Sequence

import cas_async
from cas_async import Layer, Robot

from ._common import MESSAGES, pin_malloc
from ._process_peer import stdin_closed
from ._raw_zenoh import RawAnswerer, RawReceiver, matched, raw_session
from .bench_external import RECEIVER, SENDER
from .bench_processes import FinalAckReceiver
from .bench_zenoh import CountingAnswerer, acquainted, connecting

__all__ = ["main"]


async def _framework(layer: Layer, args: argparse.Namespace) -> None:
    async with (
        connecting(args.namespace, args.connect) as transport,
        Robot(RECEIVER, [layer], transport=transport, messages=MESSAGES),
    ):
        await acquainted((layer, SENDER))
        print("ready 0", flush=True)
        await asyncio.wait_for(stdin_closed(), args.deadline)


async def _raw(args: argparse.Namespace) -> int:
    async with raw_session(args.connect) as session:
        if args.mode == "raw-throughput":
            receiver = RawReceiver(session, args.namespace, args.total, ack_last=True)
            await matched(receiver.publisher)
            print("ready 0", flush=True)
            await asyncio.wait_for(stdin_closed(), args.deadline)
            return receiver.count
        answerer = RawAnswerer(session, args.namespace)
        try:
            await matched(answerer.publisher)
            print("ready 0", flush=True)
            await asyncio.wait_for(stdin_closed(), args.deadline)
        finally:
            await answerer.stop()
        return answerer.count


async def _serve(args: argparse.Namespace) -> int:
    loop = asyncio.get_running_loop()
    try:
        if args.mode.startswith("raw"):
            count = await _raw(args)
        elif args.mode == "zenoh-throughput":
            receiver = FinalAckReceiver(args.total, loop.create_future())
            await _framework(receiver, args)
            count = receiver.count
        else:
            answerer = CountingAnswerer()
            await _framework(answerer, args)
            count = answerer.count
    except TimeoutError:
        print(f"_zenoh_peer: no stop signal within {args.deadline} s: exiting", file=sys.stderr)
        return 2
    print(f"received {count}", flush=True)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Parses the arguments, serves until told to stop, returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks._zenoh_peer")
    parser.add_argument(
        "mode", choices=["zenoh-throughput", "zenoh-rtt", "raw-throughput", "raw-rtt"]
    )
    parser.add_argument("--total", type=int, default=0)
    parser.add_argument("--namespace", default="bench")
    parser.add_argument("--connect", required=True)
    parser.add_argument("--loop", choices=["stdlib", "uvloop"], default="stdlib")
    parser.add_argument("--deadline", type=float, default=120.0)
    args = parser.parse_args(argv)
    pin_malloc()  # as the parent does by default: the same allocation pattern in every run
    return cas_async.run(_serve(args), use_uvloop=args.loop == "uvloop")


if __name__ == "__main__":
    sys.exit(main())
