"""Soak: many robots exchanging messages over loopback UDP for a while, watching for leaks.

Not a framework-against-baseline comparison like the other benchmarks, and not part
of ``python -m benchmarks`` (it lasts a minute)::

    python -m benchmarks.soak [--robots 1000] [--seconds 60] [--rate 15000] [--loop stdlib]

Every robot has two layers on one shared ``UdpTransport`` (127.0.0.1, ports the OS
picks). The top layer ticks on a timer (``wake_after``, so it handles its messages
in between): each tick sends a ``SoakNote`` to the robots ``i+1``, ``i+7`` and
``i+31`` (mod N), and, in odd robots, every ``REQUEST_EVERY``-th tick also makes a
request/reply round trip with robot ``i+1``. Every external message the top layer
receives is answered (requests) or counted, and passed down to the bottom layer,
which counts it. The load is steady, not a flood: ``--rate`` notes per second over
the swarm.

Resident memory is read after a warm-up (every robot running, buffers warm) and
again at the end; the run passes when it grew less than ``GROWTH_LIMIT``. The
result is one table line and exactly one JSON line on stdout; progress goes to
stderr. Exit status: 0 passed, 1 memory grew too much, 2 too few file descriptors.
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import json
import os
import random
import resource
import sys
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field

from cas_async import (
    ConfigurationError,
    Layer,
    Message,
    MsgType,
    RequestTimeout,
    Robot,
    ScaledClock,
    Swarm,
    UdpTransport,
    loop_factory,
    uvloop_available,
)
from cas_async.transport._fd_limit import ensure_descriptors

from ._common import LOOPBACK, pin_malloc

NEIGHBOURS = (1, 7, 31)  # robot i sends to i+1, i+7, i+31 (mod N)
REQUEST_EVERY = 5  # ticks between two round trips of one asking robot
REQUEST_TIMEOUT = 2.0  # seconds
GROWTH_LIMIT = 0.10  # of the resident memory measured after the warm-up
FD_MARGIN = 64  # descriptors besides the sockets: stdio, the loop's selector and self-pipe
PROGRESS_EVERY = 10.0  # seconds between progress lines (and RSS samples)
PAGE = os.sysconf("SC_PAGE_SIZE")
MIB = 1024 * 1024


class Note(Message):
    """The periodic message to a neighbour."""

    n: int
    text: str


class Ping(Message):
    """A request, and its reply."""

    n: int


MESSAGES = [Note, Ping]


# -- the robots ----------------------------------------------------------------------------


class Chatter(Layer):
    """Top layer: ticks every ``period`` s, talks to its peers, passes what it gets down."""

    def __init__(self, peers: Sequence[int], asks: bool, period: float, phase: float) -> None:
        self.peers = peers
        # Odd robots ask robot i+1, even ones only answer: a robot waiting for its own
        # reply handles no message meanwhile, so if every robot asked its successor,
        # the waits would chain around the ring and a little lag would end in timeouts.
        self.asks = asks
        self.period = period
        self.phase = phase  # spreads the robots' ticks over the period
        self.due = -1.0  # simulated time of the next tick; < 0 until started
        self.ticks = 0
        self.requests_done = 0
        self.requests_timed_out = 0

    async def inner_process(self) -> None:
        # Also runs after every batch of messages, not only when the timer goes off.
        now = self.clock.now()
        if self.due < 0:
            self.due = now + self.phase
            self.wake_after(self.phase)
            return
        # Half a period of slack: a timer may go off a hair early (uvloop rounds to
        # milliseconds), and a tick must never be missed, or this robot falls silent.
        if now < self.due - self.period / 2:
            return
        # An overloaded loop skips ticks rather than catching up in a burst.
        self.due = max(self.due + self.period, now + self.period / 2)
        self.wake_after(self.due - now)  # armed before any await: the schedule goes on
        self.ticks += 1
        for peer in self.peers:
            self.send(peer, Note(self.ticks, "soak"))
        if self.asks and self.ticks % REQUEST_EVERY == 0:
            try:
                await self.request(self.peers[0], Ping(self.ticks), timeout=REQUEST_TIMEOUT)
            except RequestTimeout:
                self.requests_timed_out += 1
            else:
                self.requests_done += 1

    async def handle_msg(self, msg: Message) -> None:
        if msg.msg_type == MsgType.NEGOTIATION:
            self.reply(msg, Ping(msg.n))  # type: ignore[attr-defined]
        self.send_down(msg)  # a copy: the runtime owns the received object


class Bottom(Layer):
    """Bottom layer: counts what the top layer passes down."""

    def __init__(self) -> None:
        self.count = 0

    async def store_intra_msg(self, msg: Message) -> None:
        self.count += 1


def make_robots(
    count: int, rate: float, transport: UdpTransport, clock: ScaledClock
) -> list[Robot]:
    """``count`` robots whose notes add up to ``rate`` per second."""
    period = count * len(NEIGHBOURS) / rate
    phases = random.Random(1)  # the same spread on every run
    robots = []
    for i in range(count):
        peers = list(dict.fromkeys((i + k) % count + 1 for k in NEIGHBOURS if (i + k) % count != i))
        top = Chatter(peers, (i + 1) % 2 == 1, period, phases.uniform(0, period))
        robots.append(
            Robot(i + 1, [top, Bottom()], transport=transport, clock=clock, messages=MESSAGES)
        )
    return robots


# -- measuring -----------------------------------------------------------------------------


def rss_mib() -> float:
    """Resident memory now, after a full collection (garbage awaiting a cycle is not a leak)."""
    gc.collect()
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * PAGE / MIB


def cpu_seconds() -> float:
    """CPU time this process used so far (user and system)."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


def raise_fd_limit(robots: int) -> int:
    """Makes room for one socket per robot (see ``ensure_descriptors``); returns the limit.

    Raises:
        SystemExit: (status 2) the hard limit is too low.
    """
    try:
        return ensure_descriptors(robots + FD_MARGIN)
    except ConfigurationError as error:
        print(f"soak: {robots} robots: {error}", file=sys.stderr)
        raise SystemExit(2) from None


@dataclass
class Totals:
    """What the swarm did, summed over the robots."""

    handled: int = 0
    sent: int = 0
    requests_done: int = 0
    requests_timed_out: int = 0
    dropped: Counter[str] = field(default_factory=Counter)

    @classmethod
    def of(cls, swarm: Swarm) -> Totals:
        counts = swarm.counters()
        totals = cls(
            handled=counts["received_internal"] + counts["received_external"],
            sent=counts["sent_internal"] + counts["sent_external"],
        )
        for robot in swarm:
            top = robot.layers[0]
            assert isinstance(top, Chatter)
            totals.requests_done += top.requests_done
            totals.requests_timed_out += top.requests_timed_out
            totals.dropped.update(robot.dropped)
        return totals


async def soak(robots: int, seconds: float, rate: float, warmup: float) -> dict[str, object]:
    """Runs the swarm for ``seconds`` and returns the result (the JSON line's fields)."""
    fds_before = open_fds()
    clock = ScaledClock(1.0)
    swarm = Swarm(make_robots(robots, rate, UdpTransport(host=LOOPBACK), clock))
    samples: list[float] = []
    opening = time.perf_counter()
    async with swarm:
        # The clock starts once every robot runs: binding 1,000 sockets takes a while.
        started, cpu_started = time.perf_counter(), cpu_seconds()
        fds_running = open_fds()
        running = asyncio.ensure_future(swarm.run())  # ends early only if a robot fails
        try:
            await asyncio.wait([running], timeout=warmup)
            rss_start = rss_mib()
            print(f"  soak: warm after {warmup:g} s, rss {rss_start:.1f} MiB", file=sys.stderr)
            end = started + seconds
            while not running.done() and (left := end - time.perf_counter()) > 0:
                await asyncio.wait([running], timeout=min(PROGRESS_EVERY, left))
                samples.append(round(rss_mib(), 1))
                progress(swarm, time.perf_counter() - started, samples[-1])
            rss_end = rss_mib()  # still running: the same state as at the start reading
            running_totals = Totals.of(swarm)
            elapsed = time.perf_counter() - started
            cpu = cpu_seconds() - cpu_started
        finally:
            swarm.stop()
            await asyncio.wait([running])
        running.result()  # a robot's failure ends the soak with its LayerError
    # uvloop closes a socket in the loop pass after transport.close(): let a few go by.
    for _ in range(3):
        await clock.sleep(0)
    fds_after = open_fds()
    totals = Totals.of(swarm)  # after the stop: what happened while stopping counts too
    growth = (rss_end - rss_start) / rss_start
    ticks = sum(robot.layers[0].ticks for robot in swarm)  # type: ignore[attr-defined]
    return {
        "name": "soak",
        "robots": robots,
        "seconds": round(elapsed, 1),
        "startup_s": round(started - opening, 2),
        "rate": rate,
        "handled": totals.handled,
        "handled_per_s": round(running_totals.handled / elapsed, 1),
        "sent": totals.sent,
        "ticks_per_s": round(ticks / elapsed, 1),
        "cpu_busy": round(cpu / elapsed, 3),
        "requests_done": totals.requests_done,
        "requests_timed_out": totals.requests_timed_out,
        "dropped": dict(sorted(totals.dropped.items())),
        "dropped_while_stopping": dict(sorted((totals.dropped - running_totals.dropped).items())),
        "rss_start_mib": round(rss_start, 1),
        "rss_end_mib": round(rss_end, 1),
        "rss_samples_mib": samples,
        "rss_growth": round(growth, 4),
        "sockets_open": fds_running - fds_before,
        "sockets_left_open": fds_after - fds_before,
        "ok": growth < GROWTH_LIMIT,
    }


def progress(swarm: Swarm, elapsed: float, rss: float) -> None:
    totals = Totals.of(swarm)
    print(
        f"  soak: {elapsed:5.1f} s handled {totals.handled:,} "
        f"({totals.handled / elapsed:,.0f}/s), rss {rss:.1f} MiB, "
        f"dropped {dict(totals.dropped)}",
        file=sys.stderr,
    )


# -- the command line ----------------------------------------------------------------------


def print_table(row: dict[str, object]) -> None:
    dropped = sum(row["dropped"].values())  # type: ignore[attr-defined]
    lines = [
        ("benchmark", "loop", "robots", "seconds", "handled", "handled/s", "dropped",
         "rss start MiB", "rss end MiB", "growth", "pass"),
        ("soak", str(row["loop"]), str(row["robots"]), f"{row['seconds']:.1f}",
         f"{row['handled']:,}", f"{row['handled_per_s']:,.0f}", f"{dropped:,}",
         f"{row['rss_start_mib']:.1f}", f"{row['rss_end_mib']:.1f}",
         f"{row['rss_growth']:.2%}", "PASS" if row["ok"] else "FAIL"),
    ]  # fmt: skip
    widths = [max(map(len, column)) for column in zip(*lines, strict=True)]
    for i, line in enumerate(lines):
        pairs = enumerate(zip(line, widths, strict=True))
        print("  ".join(c.ljust(w) if j < 2 else c.rjust(w) for j, (c, w) in pairs))
        if i == 0:
            print("  ".join("-" * w for w in widths))


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description="cas_async soak: robots exchanging messages over loopback UDP, "
        "checking that memory stays flat"
    )
    parser.add_argument("--robots", type=int, default=1000, help="robots (default 1000)")
    parser.add_argument("--seconds", type=float, default=60.0, help="wall time (default 60)")
    parser.add_argument(
        "--rate",
        type=float,
        default=15_000.0,
        help="notes sent per second over the whole swarm (default 15000); each is handled "
        "twice (top layer, then bottom layer), and requests and replies come on top",
    )
    parser.add_argument(
        "--warmup",
        type=float,
        default=5.0,
        help="seconds before the first memory reading (default 5, at most a quarter of the run)",
    )
    parser.add_argument("--loop", choices=["stdlib", "uvloop"], default="stdlib")
    parser.add_argument(
        "--malloc",
        choices=["default", "pinned"],
        default="default",
        help="default: glibc's own thresholds, as users run; pinned: see _common.pin_malloc",
    )
    args = parser.parse_args(argv)
    if args.robots < 2 or args.seconds <= 0 or args.rate <= 0:
        parser.error("--robots must be at least 2, --seconds and --rate positive")
    if args.loop == "uvloop" and not uvloop_available():
        parser.error("--loop uvloop: uvloop is not installed")
    malloc = "pinned" if args.malloc == "pinned" and pin_malloc() else "default"
    raise_fd_limit(args.robots)
    warmup = min(args.warmup, args.seconds / 4)
    print(
        f"  soak: {args.robots} robots, {args.seconds:g} s, {args.rate:,.0f} notes/s, "
        f"{args.loop} loop",
        file=sys.stderr,
    )
    with asyncio.Runner(loop_factory=loop_factory(use_uvloop=args.loop == "uvloop")) as runner:
        result = runner.run(soak(args.robots, args.seconds, args.rate, warmup))
    row = {"name": result.pop("name"), "loop": args.loop, "malloc": malloc, **result}
    print()
    print_table(row)
    print()
    print(json.dumps(row))
    return 0 if row["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
