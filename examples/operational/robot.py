"""One operational robot, alone in its process as a real robot is, joining the swarm on Zenoh.

Its layers are :mod:`~examples.operational.layers`' two classes, imported unchanged; only
the middleware differs: a :class:`~examples.operational.driver.StubDriver` that logs
each command (where a real robot would drive its motors) instead of the simulator. The
robot connects to the swarm's endpoint, introduces itself, meets the others at the
rendezvous they agree on, stays ``--stay`` seconds once it has met ``--company`` robots
there, and leaves (or on Ctrl-C / SIGTERM).

Run, with the swarm already up (``python -m examples.operational.simulated``)::

    python -m examples.operational.robot [--id 10] [--x 8] [--y 6] [--speed 1]
        [--company 1] [--stay 2] [--time-factor 1] [--connect tcp/127.0.0.1:7447]

Exit status: 0 once it has met the others, 1 if stopped before.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import math
import signal
import sys

import cas_async
from cas_async import ConstantSpeed, Pose, Robot, ScaledClock, ZenohTransport

from .driver import StubDriver
from .layers import Drive, Gather
from .messages import MESSAGES
from .network import ENDPOINT, NAMESPACE

__all__ = ["main"]


async def main(args: argparse.Namespace) -> bool:
    """Runs the robot until it has met its company, or is stopped; whether it met them."""
    clock = ScaledClock(args.time_factor)
    driver = StubDriver(
        args.id,
        Pose(args.x, args.y),
        clock,
        speed_profile=ConstantSpeed(args.speed),
        turn_rate=math.pi,
    )
    gather = Gather(company=args.company, stay=args.stay)
    transport = ZenohTransport(namespace=NAMESPACE, connect=[args.connect])
    robot = Robot(
        args.id, [gather, Drive(driver)], transport=transport, clock=clock, messages=MESSAGES
    )
    loop = asyncio.get_running_loop()
    for signum in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError):  # no signal handlers on Windows loops
            loop.add_signal_handler(signum, robot.stop)
    async with robot:
        print(f"robot {args.id} on Zenoh, connected to {args.connect}", flush=True)
        await robot.run()
    met = bool(gather.met)
    print(f"robot {args.id} left the swarm" + (" after meeting it" if met else ""), flush=True)
    return met


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line (see the module docs)."""
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--id", type=int, default=10, help="robot id, unique in the swarm")
    parser.add_argument("--x", type=float, default=8.0, help="where it starts, metres")
    parser.add_argument("--y", type=float, default=6.0, help="where it starts, metres")
    parser.add_argument("--speed", type=float, default=1.0, help="metres per second")
    parser.add_argument("--company", type=int, default=1, help="robots to meet before leaving")
    parser.add_argument("--stay", type=float, default=2.0, help="seconds to stay once met")
    parser.add_argument("--time-factor", type=float, default=1.0, help="simulated s per wall s")
    parser.add_argument("--connect", default=ENDPOINT, help=f"Zenoh endpoint (default {ENDPOINT})")
    return parser.parse_args(argv)


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stdout)
    sys.exit(0 if cas_async.run(main(parse_args())) else 1)
