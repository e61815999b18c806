"""A simulated rendezvous swarm in one process, on Zenoh, that operational robots can join.

Robots 1..N start on a circle around (0, 0) in an :class:`~cas_async.sim.Environment`,
each moved by a :class:`~cas_async.sim.SimulatedMiddleware`, all sharing one
:class:`~cas_async.ZenohTransport` that listens on loopback. They meet at the centre;
when a robot of another process joins (``python -m examples.operational.robot``), they
all meet at the new centroid, and when it leaves they go back to theirs. The layers are
:class:`~examples.operational.layers.Gather` and :class:`~examples.operational.layers.Drive`,
as in the operational robot.

Run (Ctrl-C stops it)::

    python -m examples.operational.simulated [--robots 3] [--radius 5] [--speed 1]
        [--time-factor 1] [--listen tcp/127.0.0.1:7447] [--duration SECONDS]

With robots of the real world in the swarm, simulated time must be real time
(``--time-factor 1``, the default); a larger factor is for demonstrations and tests,
with the operational robots given the same factor.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import math
import signal
from dataclasses import dataclass
from typing import Any

import cas_async
from cas_async import (
    Clock,
    ConstantSpeed,
    Pose,
    Robot,
    RobotId,
    ScaledClock,
    Swarm,
    Transport,
    ZenohTransport,
)
from cas_async.sim import Environment, SimulatedMiddleware

from .layers import Drive, Gather
from .messages import MESSAGES
from .network import ENDPOINT, NAMESPACE

__all__ = ["SimulatedSwarm", "build_swarm", "circle", "main"]


@dataclass(frozen=True, slots=True)
class SimulatedSwarm:
    """The robots of one process, the world they move in, and their Gather layers by id."""

    swarm: Swarm
    environment: Environment
    gathers: dict[RobotId, Gather]


def circle(count: int, radius: float) -> dict[RobotId, Pose]:
    """Robots ``1..count`` on a circle of ``radius`` around (0, 0), each facing the centre.

    Positions are rounded to the millimetre, as a surveyed start would be; the
    symmetric ones then cancel exactly, and the centre is (0, 0), not (-1e-16, 0).
    """
    poses = {}
    for robot_id in range(1, count + 1):
        angle = math.tau * (robot_id - 1) / count
        x, y = round(radius * math.cos(angle), 3), round(radius * math.sin(angle), 3)
        poses[robot_id] = Pose(x, y, angle + math.pi)
    return poses


def build_swarm(
    homes: dict[RobotId, Pose],
    *,
    transport: Transport,
    clock: Clock,
    speed: float = 1.0,
    turn_rate: float = math.pi,
) -> SimulatedSwarm:
    """Simulated robots starting at ``homes``, staying until stopped (no ``company``)."""
    environment = Environment()
    robots, gathers = [], {}
    for robot_id, pose in homes.items():
        environment.add_robot(robot_id, pose)
        middleware = SimulatedMiddleware(
            environment, robot_id, clock, turn_rate=turn_rate, speed_profile=ConstantSpeed(speed)
        )
        gather = gathers[robot_id] = Gather()
        robots.append(
            Robot(
                robot_id,
                [gather, Drive(middleware)],
                transport=transport,
                clock=clock,
                messages=MESSAGES,
            )
        )
    return SimulatedSwarm(Swarm(robots), environment, gathers)


async def main(args: argparse.Namespace) -> None:
    """Runs the swarm until Ctrl-C (or SIGTERM), or for ``--duration`` simulated seconds."""
    transport = ZenohTransport(namespace=NAMESPACE, listen=[args.listen])
    clock = ScaledClock(args.time_factor)
    simulated = build_swarm(
        circle(args.robots, args.radius), transport=transport, clock=clock, speed=args.speed
    )
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for signum in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError):  # no signal handlers on Windows loops
            loop.add_signal_handler(signum, stop.set)
    async with simulated.swarm:
        print(
            f"{args.robots} simulated robots on Zenoh {args.listen} (namespace {NAMESPACE!r}); "
            "Ctrl-C stops them",
            flush=True,
        )
        waits: list[asyncio.Future[Any]] = [asyncio.ensure_future(stop.wait())]
        if args.duration is not None:
            waits.append(asyncio.ensure_future(clock.sleep(args.duration)))
        try:
            await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for wait in waits:
                wait.cancel()
            await asyncio.gather(*waits, return_exceptions=True)
        now = clock.now()
    for robot_id in simulated.environment.robot_ids:
        pose = simulated.environment.pose_at(robot_id, now)
        print(f"robot {robot_id} at ({pose.x:.3f}, {pose.y:.3f}) after {now:.1f} simulated s")


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """The command line (see the module docs)."""
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--robots", type=int, default=3, help="simulated robots (default 3)")
    parser.add_argument("--radius", type=float, default=5.0, help="of their circle, metres")
    parser.add_argument("--speed", type=float, default=1.0, help="metres per second")
    parser.add_argument("--time-factor", type=float, default=1.0, help="simulated s per wall s")
    parser.add_argument("--listen", default=ENDPOINT, help=f"Zenoh endpoint (default {ENDPOINT})")
    parser.add_argument("--duration", type=float, default=None, help="simulated seconds to run")
    return parser.parse_args(argv)


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    cas_async.run(main(parse_args()))
