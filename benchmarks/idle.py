"""Idle: what a swarm costs while nothing happens (issue 5: 1,000 robots < 1% of a core).

Not a framework-against-baseline comparison, and not part of ``python -m benchmarks``::

    python -m benchmarks.idle [--robots 1000] [--seconds 10] [--loop stdlib|uvloop|both]
                              [--transport udp|memory]

Builds ``--robots`` robots of five layers each on one transport in this process
(UDP on 127.0.0.1 by default, one socket per robot; scaled real time), starts
them, lets them settle, then measures the CPU time this process uses (user and
system, from ``getrusage``) over ``--seconds`` of wall time while every layer
waits for a message that never comes. An idle runtime should not poll: the
target is less than 1% of one core. Voluntary context switches per second are
reported beside it: each one is the process going to sleep after a wake-up, so
they count how often something woke it.

One table line and exactly one JSON line per loop on stdout; progress on stderr.
Exit status: 0 every loop met the target, 1 one did not, 2 too few file
descriptors.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import resource
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass

from cas_async import (
    ConfigurationError,
    Layer,
    MemoryTransport,
    Robot,
    ScaledClock,
    Swarm,
    Transport,
    UdpTransport,
    loop_factory,
    uvloop_available,
)
from cas_async.transport._fd_limit import ensure_descriptors

from ._common import LOOPBACK
from ._table import print_aligned

LAYERS = 5
TARGET = 0.01  # of one core
FD_MARGIN = 64  # descriptors besides the sockets: the loop's selector and self-pipe


@dataclass(frozen=True)
class Usage:
    """Process resource counters at one instant."""

    wall: float
    user: float
    system: float
    switches: int  # voluntary context switches: the process slept until woken

    @classmethod
    def now(cls) -> Usage:
        usage = resource.getrusage(resource.RUSAGE_SELF)
        return cls(time.perf_counter(), usage.ru_utime, usage.ru_stime, usage.ru_nvcsw)

    def since(self, start: Usage) -> dict[str, float]:
        wall = self.wall - start.wall
        user, system = self.user - start.user, self.system - start.system
        return {
            "wall_s": round(wall, 3),
            "cpu_s": round(user + system, 4),
            "user_s": round(user, 4),
            "system_s": round(system, 4),
            "cpu_share": round((user + system) / wall, 5),
            "wakeups_per_s": round((self.switches - start.switches) / wall, 1),
        }


def make_swarm(robots: int, transport: Transport) -> Swarm:
    """``robots`` robots of :data:`LAYERS` plain layers: nothing to do but wait."""
    clock = ScaledClock(1.0)
    return Swarm(
        Robot(i, [Layer() for _ in range(LAYERS)], transport=transport, clock=clock)
        for i in range(1, robots + 1)
    )


async def idle(robots: int, seconds: float, settle: float, transport: str) -> dict[str, object]:
    """Starts the swarm, lets it settle, and measures it idling for ``seconds``."""
    wire: Transport = UdpTransport(host=LOOPBACK) if transport == "udp" else MemoryTransport()
    swarm = make_swarm(robots, wire)
    opening = time.perf_counter()
    async with swarm:
        started = time.perf_counter()
        running = asyncio.ensure_future(swarm.run())  # ends early only if a robot fails
        try:
            await asyncio.wait([running], timeout=settle)
            before = Usage.now()
            await asyncio.wait([running], timeout=seconds)
            after = Usage.now()
        finally:
            swarm.stop()
            await asyncio.wait([running])
        running.result()  # a robot that failed ends the benchmark with its error
    measured = after.since(before)
    return {
        "name": "idle",
        "robots": robots,
        "layers": LAYERS,
        "transport": transport,
        "startup_s": round(started - opening, 2),
        **measured,
        "target": TARGET,
        "ok": measured["cpu_share"] < TARGET,
    }


def print_table(rows: Sequence[dict[str, object]]) -> None:
    lines = [("benchmark", "loop", "transport", "robots", "seconds", "cpu s", "user s",
              "sys s", "% of a core", "wake-ups/s", "target", "pass")]  # fmt: skip
    for r in rows:
        lines.append((
            "idle", str(r["loop"]), str(r["transport"]), str(r["robots"]),
            f"{r['wall_s']:.1f}", f"{r['cpu_s']:.3f}", f"{r['user_s']:.3f}",
            f"{r['system_s']:.3f}", f"{100 * r['cpu_share']:.2f}%",  # type: ignore[operator]
            f"{r['wakeups_per_s']:,.0f}", f"< {100 * TARGET:g}%",
            "PASS" if r["ok"] else "FAIL",
        ))  # fmt: skip
    print_aligned(lines, left=(0, 1, 2))


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description="cas_async idle: the CPU an idle swarm uses (target < 1% of a core)"
    )
    parser.add_argument("--robots", type=int, default=1000, help="robots (default 1000)")
    parser.add_argument("--seconds", type=float, default=10.0, help="measured (default 10)")
    parser.add_argument(
        "--settle",
        type=float,
        default=2.0,
        help="seconds between start and measuring (default 2, at most --seconds)",
    )
    parser.add_argument("--loop", choices=["stdlib", "uvloop", "both"], default="both")
    parser.add_argument("--transport", choices=["udp", "memory"], default="udp")
    args = parser.parse_args(argv)
    if args.robots < 1 or args.seconds <= 0 or args.settle < 0:
        parser.error("--robots must be at least 1, --seconds positive, --settle >= 0")
    loops = ["stdlib", "uvloop"] if args.loop == "both" else [args.loop]
    if "uvloop" in loops and not uvloop_available():
        if args.loop == "uvloop":
            parser.error("--loop uvloop: uvloop is not installed")
        print("idle: uvloop is not installed: skipping it", file=sys.stderr)
        loops.remove("uvloop")
    if args.transport == "udp":
        try:
            ensure_descriptors(args.robots + FD_MARGIN)
        except ConfigurationError as error:
            print(f"idle: {args.robots} robots: {error}", file=sys.stderr)
            return 2
    settle = min(args.settle, args.seconds)
    rows = []
    for loop in loops:
        print(
            f"  idle: {args.robots} robots x {LAYERS} layers on {args.transport}, {loop} loop, "
            f"settling {settle:g} s, measuring {args.seconds:g} s",
            file=sys.stderr,
        )
        factory = loop_factory(use_uvloop=loop == "uvloop")
        with asyncio.Runner(loop_factory=factory) as runner:
            result = runner.run(idle(args.robots, args.seconds, settle, args.transport))
        rows.append({"name": result.pop("name"), "loop": loop, **result})
    print()
    print_table(rows)
    print()
    for row in rows:
        print(json.dumps(row))
    return 0 if all(row["ok"] for row in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
