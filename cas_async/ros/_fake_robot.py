"""A stand-in ROS 2 robot on rmw_zenoh: for tests, demos, and users without a robot.

:class:`FakeRobot` is what a differential-drive robot running ``rmw_zenohd`` looks
like from the network, without ROS:

* a Zenoh **router** configured like ``rmw_zenohd`` (router mode, multicast
  scouting off, gossip on; loopback here, ``tcp/[::]:7447`` on a robot);
* behind it, the robot's **node** in a *peer* session connected to the router,
  as rmw_zenoh's sessions are (listening on loopback, port picked by the OS), with
  its node token and the tokens of its ``/cmd_vel`` subscription and ``/odom``
  publisher, written as rmw_zenoh writes them;
* a **unicycle**: every tick (``rate`` per second) it integrates the last
  ``/cmd_vel`` (linear x, angular z; clamped to ``max_speed`` and ``max_turn_rate``)
  exactly over the tick and publishes ``nav_msgs/msg/Odometry`` in frame ``odom``,
  child ``base_footprint``. A robot not commanded for ``cmd_vel_timeout`` seconds
  stops, as ``diff_drive_controller`` does.

It reads the graph like rmw_zenoh's graph cache (:func:`~cas_async.ros.parse_token`)
and reports every entity that comes and goes to ``on_graph``. Run it with
``python -m cas_async.ros fake-robot``.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from typing import Any, Final

from .. import ConfigurationError, Pose, ScaledClock
from ..transport.zenoh import loopback_config
from ._endpoints import RosSubscription
from ._extra import import_zenoh
from ._graph import GraphEntity
from ._link import RosLink
from ._message_types import DISTRO

__all__ = ["FakeRobot"]

_ODOM: Final = "nav_msgs/msg/Odometry"


class FakeRobot:
    """A simulated differential-drive robot behind a router configured like ``rmw_zenohd``.

    Args:
        listen: the router's endpoint (``tcp/127.0.0.1:7447``: loopback only).
        node: the robot's node name.
        namespace: the robot's namespace (its topics resolve under it).
        domain_id: ``ROS_DOMAIN_ID``.
        distro: the distribution its types come from.
        start: its pose in the ``odom`` frame at start.
        rate: ticks (odometry messages) per wall-clock second.
        time_factor: simulated seconds per wall second (1: a real robot).
        max_speed: the fastest it drives, m/s (either way).
        max_turn_rate: the fastest it turns, rad/s.
        cmd_vel_timeout: simulated seconds without a command before it stops.
        cmd_vel_type: ``geometry_msgs/msg/Twist`` or ``geometry_msgs/msg/TwistStamped``.
        on_graph: called with ``(appeared, entity)`` for each entity of the graph
            that comes or goes, its own included.

    Raises:
        ConfigurationError: a bad parameter.
    """

    def __init__(
        self,
        *,
        listen: str = "tcp/127.0.0.1:7447",
        node: str = "fake_robot",
        namespace: str = "/",
        domain_id: int = 0,
        distro: str = DISTRO,
        start: Pose | None = None,
        rate: float = 50.0,
        time_factor: float = 1.0,
        max_speed: float = 1.0,
        max_turn_rate: float = 2.0,
        cmd_vel_timeout: float = 0.5,
        cmd_vel_type: str = "geometry_msgs/msg/Twist",
        on_graph: Callable[[bool, GraphEntity], None] | None = None,
    ) -> None:
        for name, value in (
            ("rate", rate),
            ("max_speed", max_speed),
            ("max_turn_rate", max_turn_rate),
            ("cmd_vel_timeout", cmd_vel_timeout),
        ):
            if not (value > 0 and math.isfinite(value)):
                raise ConfigurationError(
                    f"FakeRobot {name} must be a finite number > 0, got {value!r}"
                )
        if cmd_vel_type not in ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped"):
            raise ConfigurationError(
                f"FakeRobot cmd_vel_type must be Twist or TwistStamped, got {cmd_vel_type!r}"
            )
        self.listen = listen
        self.link = RosLink(
            node,
            namespace=namespace,
            domain_id=domain_id,
            distro=distro,
            connect=[listen],
            mode="peer",
            listen=["tcp/127.0.0.1:0"],
        )
        self.pose = start if start is not None else Pose(0.0, 0.0)
        self.velocity = (0.0, 0.0)
        self.clock = ScaledClock(time_factor)
        self.rate = rate
        self.max_speed = max_speed
        self.max_turn_rate = max_turn_rate
        self.cmd_vel_timeout = cmd_vel_timeout
        self.cmd_vel_type = cmd_vel_type
        self.ticks = 0
        self.commands: RosSubscription | None = None
        """The ``cmd_vel`` subscription (its counts), once :meth:`run` has begun."""
        self._on_graph = on_graph
        self._router: Any = None
        self._seen: dict[str, GraphEntity] = {}

    async def __aenter__(self) -> FakeRobot:
        zenoh = import_zenoh()
        try:
            self._router = await asyncio.to_thread(
                zenoh.open, loopback_config(mode="router", listen=[self.listen])
            )
        except Exception as exc:  # zenoh.ZError: the port is taken, say
            raise ConfigurationError(
                f"the fake robot's router cannot listen on {self.listen}: {exc}"
            ) from exc
        try:
            await self.link.open()
        except BaseException:
            self.close()
            raise
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Closes the node, then the router; idempotent."""
        self.link.close()
        router, self._router = self._router, None
        if router is not None:
            router.close()

    async def run(self, stop: asyncio.Event) -> None:
        """Drives from ``/cmd_vel`` and publishes ``/odom`` until ``stop`` is set."""
        cmd_vel = self.commands = self.link.subscribe("cmd_vel", self.cmd_vel_type)
        odom = self.link.publisher("odom", _ODOM)
        clock, period = self.clock, self.clock.time_factor / self.rate
        clock.start()
        start = last = commanded = clock.now()
        heard = 0
        stopping = asyncio.ensure_future(stop.wait())
        try:
            while not stop.is_set():
                self._report_graph()
                now = clock.now()
                if cmd_vel.received != heard and cmd_vel.latest is not None:
                    heard, commanded = cmd_vel.received, now
                    twist = cmd_vel.latest.get("twist", cmd_vel.latest)  # TwistStamped has one
                    self.velocity = (
                        _clamp(twist["linear"]["x"], self.max_speed),
                        _clamp(twist["angular"]["z"], self.max_turn_rate),
                    )
                cmd_vel.clear()
                if now - commanded > self.cmd_vel_timeout:
                    self.velocity = (0.0, 0.0)
                self.pose = _integrate(self.pose, *self.velocity, now - last)
                last = now
                odom.publish(self._odometry())
                self.ticks += 1
                tick = asyncio.ensure_future(clock.sleep_until(start + self.ticks * period))
                try:
                    await asyncio.wait([tick, stopping], return_when=asyncio.FIRST_COMPLETED)
                finally:
                    tick.cancel()
        finally:
            stopping.cancel()
            self._report_graph()

    def _odometry(self) -> dict[str, Any]:
        ns = self.link.clock_ns()
        pose, (speed, turn) = self.pose, self.velocity
        return {
            "header": {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": "odom"},
            "child_frame_id": "base_footprint",
            "pose": {
                "pose": {
                    "position": {"x": pose.x, "y": pose.y},
                    "orientation": {
                        "z": math.sin(pose.heading / 2),
                        "w": math.cos(pose.heading / 2),
                    },
                }
            },
            "twist": {"twist": {"linear": {"x": speed}, "angular": {"z": turn}}},
        }

    def _report_graph(self) -> None:
        now = {entity.token(): entity for entity in self.link.graph()}
        if self._on_graph is not None:
            for key in self._seen.keys() - now.keys():
                self._on_graph(False, self._seen[key])
            for key in now.keys() - self._seen.keys():
                self._on_graph(True, now[key])
        self._seen = now


def _clamp(value: float, limit: float) -> float:
    return max(-limit, min(limit, float(value)))


def _integrate(pose: Pose, speed: float, turn: float, dt: float) -> Pose:
    """The pose after ``dt`` seconds at constant ``speed`` and ``turn`` (exact unicycle)."""
    if dt <= 0 or (speed == 0 and turn == 0):
        return pose
    heading = pose.heading
    if abs(turn) < 1e-9:
        return Pose(
            pose.x + speed * dt * math.cos(heading),
            pose.y + speed * dt * math.sin(heading),
            heading,
        )
    after = heading + turn * dt
    radius = speed / turn
    return Pose(
        pose.x + radius * (math.sin(after) - math.sin(heading)),
        pose.y - radius * (math.cos(after) - math.cos(heading)),
        after,
    )
