"""The child process of ``bench_zenoh``: robot 2, over Zenoh or UDP.

Usage::

    python -m benchmarks._zenoh_peer zenoh-throughput --total N --namespace NS --connect E \
        --loop L --deadline S
    python -m benchmarks._zenoh_peer zenoh-rtt --namespace NS --connect E --loop L --deadline S
    python -m benchmarks._zenoh_peer udp-rtt --sender-port P --loop L --deadline S

``zenoh-throughput``: robot 2 (:class:`~benchmarks.bench_processes.FinalAckReceiver`)
on a ``ZenohTransport`` connecting to endpoint ``E`` (the parent's session), under
namespace ``NS``. ``zenoh-rtt``: robot 2 answering requests
(:class:`~benchmarks.bench_zenoh.CountingAnswerer`) on the same. ``udp-rtt``: that
answerer on a ``UdpTransport`` that knows robot 1 at ``127.0.0.1:P``.

Protocol with the parent (``bench_processes.peer_process``): prints ``ready PORT``
once robot 2 can reach robot 1 (over Zenoh: once it knows robot 1's token; ``PORT``
is then 0, the parent needs none); runs until its stdin closes (the parent is done,
or died); then prints ``received COUNT`` (messages received, or requests answered)
and exits 0. Exits 2 without waiting further after ``--deadline`` seconds, and 1
when robot 1 is not seen within ``KNOW_LIMIT``. The Zenoh session is closed on
every way out: a process with an open Zenoh subscriber does not exit.
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from collections.abc import Sequence

import cas_async
from cas_async import Layer, Robot, UdpDirectory, UdpTransport

from ._common import LOOPBACK, MESSAGES, pin_malloc
from ._process_peer import stdin_closed
from .bench_external import RECEIVER, SENDER
from .bench_processes import FinalAckReceiver, bound_port
from .bench_zenoh import CountingAnswerer, acquainted, connecting

__all__ = ["main"]


async def _zenoh(layer: Layer, namespace: str, connect: str, deadline: float) -> None:
    async with (
        connecting(namespace, connect) as transport,
        Robot(RECEIVER, [layer], transport=transport, messages=MESSAGES),
    ):
        await acquainted((layer, SENDER))
        print("ready 0", flush=True)
        await asyncio.wait_for(stdin_closed(), deadline)


async def _udp(layer: Layer, sender_port: int, deadline: float) -> None:
    transport = UdpTransport(UdpDirectory({SENDER: (LOOPBACK, sender_port)}))
    async with Robot(RECEIVER, [layer], transport=transport, messages=MESSAGES) as robot:
        print(f"ready {bound_port(robot)}", flush=True)
        await asyncio.wait_for(stdin_closed(), deadline)


async def _serve(args: argparse.Namespace) -> int:
    loop = asyncio.get_running_loop()
    counter: FinalAckReceiver | CountingAnswerer
    try:
        if args.mode == "zenoh-throughput":
            counter = FinalAckReceiver(args.total, loop.create_future())
            await _zenoh(counter, args.namespace, args.connect, args.deadline)
        elif args.mode == "zenoh-rtt":
            counter = CountingAnswerer()
            await _zenoh(counter, args.namespace, args.connect, args.deadline)
        else:
            counter = CountingAnswerer()
            await _udp(counter, args.sender_port, args.deadline)
    except TimeoutError:
        print(f"_zenoh_peer: no stop signal within {args.deadline} s: exiting", file=sys.stderr)
        return 2
    print(f"received {counter.count}", flush=True)
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Parses the arguments, serves until told to stop, returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m benchmarks._zenoh_peer")
    parser.add_argument("mode", choices=["zenoh-throughput", "zenoh-rtt", "udp-rtt"])
    parser.add_argument("--total", type=int, default=0)
    parser.add_argument("--namespace", default="bench")
    parser.add_argument("--connect", default="")
    parser.add_argument("--sender-port", type=int, default=0)
    parser.add_argument("--loop", choices=["stdlib", "uvloop"], default="stdlib")
    parser.add_argument("--deadline", type=float, default=120.0)
    args = parser.parse_args(argv)
    if args.mode.startswith("zenoh") and not args.connect:
        parser.error(f"{args.mode} needs --connect")
    pin_malloc()  # as the parent does by default: the same allocation pattern in every run
    return cas_async.run(_serve(args), use_uvloop=args.loop == "uvloop")


if __name__ == "__main__":
    sys.exit(main())
