"""One operational robot, alone in its process as a real robot is, joining the swarm on Zenoh.

Its layers are :mod:`~examples.operational.layers`' two classes, imported unchanged; only
the middleware differs: a :class:`~examples.operational.driver.StubDriver` that logs
each command (where a real robot would drive its motors) instead of the simulator. The
robot connects to the swarm's endpoint, introduces itself, meets the others at the
rendezvous they agree on, stays ``--stay`` seconds once it has met ``--company`` robots
there, and leaves (or on Ctrl-C / SIGTERM).

With ``--ros ENDPOINT`` the middleware is a ROS 2 robot instead: a
:class:`~cas_async.ros.RosDiffDrive` that drives it with ``/cmd_vel`` and reads its
pose from ``/odom``, through a :class:`~cas_async.ros.RosLink` connected to the
robot's ``rmw_zenohd`` at ``ENDPOINT`` (or to ``python -m cas_async.ros fake-robot``).
``--x --y --heading`` then say where the robot's ``odom`` frame lies in the swarm's.

Run, with the swarm already up (``python -m examples.operational.simulated``)::

    python -m examples.operational.robot [--id 10] [--x 8] [--y 6] [--speed 1]
        [--company 1] [--stay 2] [--time-factor 1] [--connect tcp/127.0.0.1:7447]
        [--ros tcp/ROBOT:7447 [--heading 0] [--ros-namespace /] [--ros-domain 0]
         [--cmd-vel-type geometry_msgs/msg/Twist]]

Exit status: 0 once it has met the others, 1 if stopped before.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import signal
import sys

import cas_async
from cas_async import Clock, ConstantSpeed, Middleware, Pose, Robot, ScaledClock, ZenohTransport
from cas_async.ros import RosDiffDrive, RosLink

from .driver import StubDriver
from .layers import Drive, Gather
from .messages import MESSAGES
from .network import ENDPOINT, NAMESPACE

__all__ = ["main"]


async def middleware(
    args: argparse.Namespace, clock: Clock, stack: contextlib.AsyncExitStack
) -> Middleware:
    """The stub driver, or (``--ros``) a ROS 2 robot found and checked at its endpoint."""
    speed = ConstantSpeed(args.speed)
    if args.ros is None:
        return StubDriver(args.id, Pose(args.x, args.y), clock, speed_profile=speed)
    link = await stack.enter_async_context(
        RosLink(
            f"cas_robot_{args.id}",
            namespace=args.ros_namespace,
            domain_id=args.ros_domain,
            connect=args.ros,
        )
    )
    drive = RosDiffDrive(
        link,
        args.id,
        clock,
        speed_profile=speed,
        origin=Pose(args.x, args.y, args.heading),
        cmd_vel_type=args.cmd_vel_type,
        # A robot's odometry comes at its own pace in real time: a second of silence
        # on the wall clock, whatever the time factor (timeouts are simulated seconds),
        # and ten wall seconds to find its topics.
        odom_timeout=max(1.0, args.time_factor),
        discovery_timeout=10.0 * max(1.0, args.time_factor),
    )
    await stack.enter_async_context(drive)  # found, its types checked, its first odometry
    print(f"robot {args.id} drives the ROS 2 robot at {args.ros} ({link.nodes()})", flush=True)
    return drive


async def main(args: argparse.Namespace) -> bool:
    """Runs the robot until it has met its company, or is stopped; whether it met them."""
    async with contextlib.AsyncExitStack() as stack:
        return await _run(args, stack)


async def _run(args: argparse.Namespace, stack: contextlib.AsyncExitStack) -> bool:
    clock = ScaledClock(args.time_factor)
    driver = await middleware(args, clock, stack)
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
    parser.add_argument(
        "--ros", default=None, help="drive the ROS 2 robot whose rmw_zenohd is here"
    )
    parser.add_argument("--heading", type=float, default=0.0, help="start heading, radians")
    parser.add_argument("--ros-namespace", default="/", help="the ROS 2 robot's namespace")
    parser.add_argument("--ros-domain", type=int, default=0, help="its ROS_DOMAIN_ID")
    parser.add_argument(
        "--cmd-vel-type",
        default="geometry_msgs/msg/Twist",
        choices=("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped"),
        help="what the robot's controller subscribes to on cmd_vel",
    )
    return parser.parse_args(argv)


if __name__ == "__main__":
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stdout)
    sys.exit(0 if cas_async.run(main(parse_args())) else 1)
