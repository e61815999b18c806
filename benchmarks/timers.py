"""Timers: how late a loop timer goes off, per event loop (what a ScaledClock inherits).

Not a framework-against-baseline comparison, and not part of ``python -m benchmarks``::

    python -m benchmarks.timers [--timers 2000] [--runs 3]

On each loop (the stdlib loop with the stock epoll selector, the stdlib loop
``cas_async.loop_factory`` makes, with :mod:`cas_async._time._precise_selector`, and
uvloop when installed), one task arms ``--timers`` timers one after the other,
each due 0.1 to 3 ms after the previous one went off (delays drawn from a fixed
seed, the same on every loop), and records by how much each went off after its
instant (negative: early; uvloop rounds delays to the nearest millisecond, which
is why a ScaledClock pads its deadlines there). Under a ScaledClock, a timer's
lateness times the time factor is simulated time lost (at factor 100, 0.5 ms
late is 50 ms simulated).

Median, 90th percentile and maximum lateness in microseconds: the medians of
``--runs`` runs, one table line and one JSON line per loop on stdout.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import random
import statistics
import sys
import time
from collections.abc import Callable

from cas_async import loop_factory, uvloop_available

from ._table import print_aligned

SEED = 5


async def lateness(delays: list[float]) -> list[float]:
    """How late (in seconds, negative: early) each of a chain of timers went off.

    Read on ``time.monotonic``, not on ``loop.time()``: uvloop's counts whole
    milliseconds.
    """
    loop = asyncio.get_running_loop()
    late = []
    for delay in delays:
        woken: asyncio.Future[float] = loop.create_future()
        due = time.monotonic() + delay
        loop.call_later(delay, lambda f=woken: f.set_result(time.monotonic()))
        late.append(await woken - due)
    return late


def loops() -> dict[str, Callable[[], asyncio.AbstractEventLoop]]:
    found = {
        "stdlib epoll (stock)": asyncio.new_event_loop,
        "stdlib (loop_factory)": loop_factory(use_uvloop=False),
    }
    if uvloop_available():
        found["uvloop"] = loop_factory(use_uvloop=True)
    return found


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.timers", description=__doc__)
    parser.add_argument("--timers", type=int, default=2000, help="timers per run")
    parser.add_argument("--runs", type=int, default=3, help="runs per loop (median reported)")
    args = parser.parse_args(argv)
    rng = random.Random(SEED)
    delays = [rng.uniform(0.0001, 0.003) for _ in range(args.timers)]
    rows = []
    for name, factory in loops().items():
        runs = []
        for run in range(args.runs):
            with asyncio.Runner(loop_factory=factory) as runner:
                late = sorted(runner.run(lateness(delays)))
            early = sum(1 for t in late if t < 0) / len(late)
            runs.append((
                statistics.median(late), late[int(0.9 * len(late))], late[-1], early
            ))  # fmt: skip
            print(f"  {name} run {run + 1}: median {runs[-1][0] * 1e6:.0f} us", file=sys.stderr)
        median, p90, worst = (statistics.median(r[i] for r in runs) * 1e6 for i in range(3))
        early = statistics.median(r[3] for r in runs)
        rows.append({
            "name": "timer_lateness", "loop": name, "timers": args.timers, "runs": args.runs,
            "median_us": round(median, 1), "p90_us": round(p90, 1), "max_us": round(worst, 1),
            "early": round(early, 3),
        })  # fmt: skip
    lines = [("loop", "median us", "p90 us", "max us", "early")]
    for row in rows:
        lines.append((
            str(row["loop"]), f"{row['median_us']:.1f}", f"{row['p90_us']:.1f}",
            f"{row['max_us']:.1f}", f"{row['early']:.1%}",
        ))  # fmt: skip
    print_aligned(lines, left=(0,))
    for row in rows:
        print(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
