"""``python -m cas_async.ros``: a fake robot to drive, and a look at a robot's ROS graph.

* ``fake-robot``: a stand-in ROS 2 robot (:class:`~cas_async.ros.FakeRobot`) until
  Ctrl-C or SIGTERM (or ``--lifetime``); prints ``fake robot ready`` once it is up,
  every entity of the graph that comes (``graph +``) or goes (``graph -``) as its
  graph cache reads the tokens, and a summary when it stops.
* ``graph``: connects to a router as a client, waits ``--wait`` seconds for the
  tokens, and prints the nodes and topics with their types and hashes, as
  ``ros2 node list`` and ``ros2 topic list -t`` would (a check that a robot is
  reachable, with no ROS installed).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import signal
import sys

from .. import CasError, Pose, ScaledClock, run
from ._fake_robot import FakeRobot
from ._graph import GraphEntity
from ._link import RosLink
from ._message_types import DISTRO, DISTROS

__all__ = ["main"]


def _describe(entity: GraphEntity) -> str:
    if entity.kind == "NN":
        return f"NN {entity.node_fqn}"
    qos = entity.qos.to_key() if entity.qos is not None else ""
    topic = f"{entity.topic} {entity.type_name} {entity.type_hash}"
    return f"{entity.kind} {topic} {qos} {entity.node_fqn}"


async def _fake_robot(args: argparse.Namespace) -> int:
    def on_graph(appeared: bool, entity: GraphEntity) -> None:
        print(f"graph {'+' if appeared else '-'} {_describe(entity)}", flush=True)

    robot = FakeRobot(
        listen=args.listen,
        node=args.node,
        namespace=args.namespace,
        domain_id=args.domain,
        distro=args.distro,
        start=Pose(args.x, args.y, args.heading),
        rate=args.rate,
        time_factor=args.time_factor,
        cmd_vel_type=args.cmd_vel_type,
        on_graph=on_graph,
    )
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for signum in (signal.SIGINT, signal.SIGTERM):
        with contextlib.suppress(NotImplementedError):  # no signal handlers on Windows loops
            loop.add_signal_handler(signum, stop.set)
    if args.lifetime is not None:
        loop.call_later(args.lifetime, stop.set)
    async with robot:
        print(
            f"fake ROS 2 robot {robot.link.namespace.rstrip('/')}/{args.node} behind a router on "
            f"{args.listen} (domain {args.domain}, {args.distro}); Ctrl-C stops it",
            flush=True,
        )
        print("fake robot ready", flush=True)
        await robot.run(stop)
        pose = robot.pose
        commands = robot.commands
    received, dropped = (0, {}) if commands is None else (commands.received, commands.dropped)
    print(
        f"fake robot stopped at ({pose.x:.3f}, {pose.y:.3f}, heading {pose.heading:.3f}) after "
        f"{robot.ticks} odometry messages; cmd_vel received {received}, dropped {dropped}; "
        f"tokens refused {robot.link.bad_tokens}; session closed: {robot.link.session is None}",
        flush=True,
    )
    return 0


async def _graph(args: argparse.Namespace) -> int:
    async with RosLink(
        "cas_async_graph", domain_id=args.domain, distro=args.distro, connect=args.connect
    ) as link:
        await ScaledClock().sleep(args.wait)
        print("nodes:")
        for node in link.nodes():
            print(f"  {node}")
        print("topics:")
        topics = sorted(
            {
                (e.topic, e.type_name, e.type_hash, e.kind)
                for e in link.graph()
                if e.kind in ("MP", "MS") and e.zid != link.zid
            }
        )
        for topic, type_name, type_hash, kind in topics:
            role = "publisher" if kind == "MP" else "subscription"
            print(f"  {topic} [{type_name}] {type_hash} {role}")
    return 0


def parser() -> argparse.ArgumentParser:
    """The command line (see the module docs)."""
    top = argparse.ArgumentParser(
        prog="python -m cas_async.ros", description=(__doc__ or "").splitlines()[0]
    )
    commands = top.add_subparsers(dest="command", required=True)
    fake = commands.add_parser("fake-robot", help="a stand-in ROS 2 robot on rmw_zenoh")
    fake.add_argument("--listen", default="tcp/127.0.0.1:7447", help="the router's endpoint")
    fake.add_argument("--node", default="fake_robot", help="the robot's node name")
    fake.add_argument("--namespace", default="/", help="the robot's namespace")
    fake.add_argument("--domain", type=int, default=0, help="ROS_DOMAIN_ID")
    fake.add_argument("--distro", default=DISTRO, choices=DISTROS)
    fake.add_argument("--x", type=float, default=0.0, help="start, metres in the odom frame")
    fake.add_argument("--y", type=float, default=0.0, help="start, metres in the odom frame")
    fake.add_argument("--heading", type=float, default=0.0, help="start heading, radians")
    fake.add_argument("--rate", type=float, default=50.0, help="odometry messages per second")
    fake.add_argument("--time-factor", type=float, default=1.0, help="simulated s per wall s")
    fake.add_argument(
        "--cmd-vel-type",
        default="geometry_msgs/msg/Twist",
        choices=("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped"),
    )
    fake.add_argument("--lifetime", type=float, default=None, help="wall seconds, then stop")
    graph = commands.add_parser("graph", help="the nodes and topics a router knows")
    graph.add_argument("--connect", default="tcp/127.0.0.1:7447", help="the router's endpoint")
    graph.add_argument("--domain", type=int, default=0, help="ROS_DOMAIN_ID")
    graph.add_argument("--distro", default=DISTRO, choices=DISTROS)
    graph.add_argument("--wait", type=float, default=1.0, help="seconds to gather tokens")
    return top


def main(argv: list[str] | None = None) -> int:
    """Runs a command; its exit status (2 with a one-line message on a ``CasError``)."""
    args = parser().parse_args(argv)
    command = _fake_robot if args.command == "fake-robot" else _graph
    try:
        return run(command(args))
    except CasError as exc:
        print(f"python -m cas_async.ros {args.command}: {exc}", file=sys.stderr)
        return 2
