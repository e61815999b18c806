"""A :class:`~cas_async.Middleware` for ROS 2 differential-drive robots: cmd_vel out, odom in.

:class:`RosDiffDrive` turns the layers' ``move_to`` / ``rotate_to`` into velocity
commands with :class:`~cas_async.ros.DiffDriveController` (turn toward the goal,
drive, stop within a tolerance), one command per odometry message, and reports the
pose from odometry. Poses are in the layers' frame: ``origin`` is where the robot's
``odom`` frame lies in it (a robot's odometry starts where it booted).

Time-outs and errors say what to fix:

* :meth:`~RosDiffDrive.start` waits ``discovery_timeout`` for a node that subscribes
  to ``cmd_vel`` and one that publishes ``odom`` (:class:`~cas_async.ros.RosTimeout`
  naming the nodes seen), refuses a robot whose topics have another type or type
  hash (``ConfigurationError`` naming both, e.g. a robot that wants ``TwistStamped``),
  and waits for the first odometry. A token of another type is anyone's to declare:
  an endpoint of the right type seen within :data:`MISMATCH_GRACE` after it (or
  before) is the robot's, and the start goes on;
* a move raises :class:`~cas_async.ros.RosTimeout` when odometry stops for
  ``odom_timeout`` or the goal is not reached in ``move_timeout`` (by default three
  times the time the move should take, plus 5 s); the robot is told to stop first,
  as it is when a move is cancelled.

Odometry is taken from a subscription that drops samples over :data:`ODOM_MAX_BYTES`
and samples holding a NaN or an infinity (see :class:`~cas_async.ros.RosSubscription`);
a pose that still cannot be used (a position past a float's range once moved into
the layers' frame) is dropped and counted there too (``unusable_pose``). A move goes
on with the next good odometry.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Callable
from typing import Any, Final, final

import numpy as np

from .. import (
    Clock,
    ConfigurationError,
    Middleware,
    Pose,
    Positions,
    RobotId,
    RobotStateError,
    SimulationError,
    SpeedProfile,
)
from ._controller import DiffDriveController, DriveTuning
from ._endpoints import RosPublisher, RosSubscription
from ._exceptions import RosTimeout
from ._graph import GraphEntity, Kind
from ._link import RosLink

__all__ = ["MISMATCH_GRACE", "ODOM_MAX_BYTES", "RosDiffDrive"]

ODOM_MAX_BYTES: Final = 4096
"""Bytes of an odometry sample, at most (one is about 700, with two short frame ids)."""
MISMATCH_GRACE: Final = 2.0
"""Seconds (of the drive's clock) that an endpoint of the right type has to show up
after one of another type was seen, before the start is refused."""

_TWIST: Final = "geometry_msgs/msg/Twist"
_STAMPED: Final = "geometry_msgs/msg/TwistStamped"
_ODOM: Final = "nav_msgs/msg/Odometry"


def _nobody() -> Positions:
    ids, xy = np.empty(0, dtype=np.int64), np.empty((0, 2), dtype=np.float64)
    ids.flags.writeable = xy.flags.writeable = False
    return Positions(ids, xy)


@final
class RosDiffDrive(Middleware):
    """Drives a ROS 2 differential-drive robot through a :class:`~cas_async.ros.RosLink`.

    Args:
        link: an open link to the robot's router.
        robot_id: the robot's id in the swarm.
        clock: the robot's clock (pass the same one to the ``Robot``); time-outs
            and the speed profile run on it.
        speed_profile: the profile of the first translation (its speed is the
            cruise speed commanded).
        origin: the pose of the robot's ``odom`` frame in the layers' frame.
        cmd_vel: the velocity topic (relative names resolve in the link's namespace).
        odom: the odometry topic.
        cmd_vel_type: ``geometry_msgs/msg/Twist`` or ``geometry_msgs/msg/TwistStamped``
            (what the robot's controller subscribes to).
        tuning: the controller's parameters.
        discovery_timeout: seconds :meth:`start` waits for the robot's topics.
        odom_timeout: seconds without odometry that fail a move or :meth:`start`.
        move_timeout: seconds a move may take; ``None``: three times its expected
            time plus 5 s. Every time-out is in seconds of ``clock``.

    Raises:
        ConfigurationError: a bad parameter.
    """

    def __init__(
        self,
        link: RosLink,
        robot_id: RobotId,
        clock: Clock,
        *,
        speed_profile: SpeedProfile,
        origin: Pose | None = None,
        cmd_vel: str = "cmd_vel",
        odom: str = "odom",
        cmd_vel_type: str = _TWIST,
        tuning: DriveTuning | None = None,
        discovery_timeout: float = 10.0,
        odom_timeout: float = 1.0,
        move_timeout: float | None = None,
    ) -> None:
        if cmd_vel_type not in (_TWIST, _STAMPED):
            raise ConfigurationError(
                f"robot {robot_id}: cmd_vel_type must be {_TWIST} or {_STAMPED}, "
                f"got {cmd_vel_type!r}"
            )
        for name, value in (
            ("discovery_timeout", discovery_timeout),
            ("odom_timeout", odom_timeout),
        ):
            if not value > 0:
                raise ConfigurationError(f"robot {robot_id}: {name} must be > 0 s, got {value!r}")
        if move_timeout is not None and not move_timeout > 0:
            raise ConfigurationError(
                f"robot {robot_id}: move_timeout must be > 0 s, got {move_timeout!r}"
            )
        self._link = link
        self._robot_id = robot_id
        self._clock = clock
        self._profile = speed_profile
        self._origin = origin if origin is not None else Pose(0.0, 0.0)
        self._topics = (link.resolve(cmd_vel), link.resolve(odom))
        self._cmd_vel_type = cmd_vel_type
        self._controller = DiffDriveController(tuning)
        self._discovery_timeout = discovery_timeout
        self._odom_timeout = odom_timeout
        self._move_timeout = move_timeout
        self._publisher: RosPublisher | None = None
        self._odometry: RosSubscription | None = None
        self._pose: Pose | None = None  # the last odometry that made a pose
        self._moving = False

    # -- lifecycle ---------------------------------------------------------------------

    async def start(self) -> None:
        """Finds the robot's topics, checks their types, and waits for its first odometry.

        Raises:
            RosTimeout: no node subscribes to ``cmd_vel`` or publishes ``odom`` within
                ``discovery_timeout``, or no odometry within ``odom_timeout`` after.
            ConfigurationError: the robot's topics have another type or type hash.
            RobotStateError: started twice, or the link is not open.
        """
        if self._publisher is not None:
            raise RobotStateError(f"robot {self._robot_id}: RosDiffDrive started already")
        cmd_vel, odom = self._topics
        self._publisher = self._link.publisher(cmd_vel, self._cmd_vel_type)
        self._odometry = self._link.subscribe(odom, _ODOM, max_bytes=ODOM_MAX_BYTES)
        try:
            wanted: tuple[tuple[str, Kind, GraphEntity], ...] = (
                (cmd_vel, "MS", self._publisher.entity),
                (odom, "MP", self._odometry.entity),
            )
            for topic, kind, ours in wanted:
                await self._find(topic, kind, ours)
            await self._next_odometry("start")
        except BaseException:
            self.close()
            raise

    async def _find(self, topic: str, kind: Kind, ours: GraphEntity) -> None:
        """Waits for the robot's endpoint on ``topic``: one of our type and hash.

        Raises:
            RosTimeout: no endpoint at all within ``discovery_timeout``.
            ConfigurationError: only endpoints of another type or hash, still after
                :data:`MISMATCH_GRACE` (naming the first such).
        """
        link, match = self._link, (ours.type_name, ours.type_hash)
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self._clock.loop_seconds(self._discovery_timeout)
        peer = await link.wait_for(topic, kind, deadline - loop.time())
        if (peer.type_name, peer.type_hash) == match:
            return
        grace = min(self._clock.loop_seconds(MISMATCH_GRACE), deadline - loop.time())
        try:
            await link.wait_for(topic, kind, max(grace, 0.0), match=match)
            return
        except RosTimeout:
            pass
        others = [e for e in link.endpoints(topic, kind) if (e.type_name, e.type_hash) != match]
        peer = others[0] if others else peer
        self._check(
            topic, ours.type_name, ours.type_hash, peer.type_name, peer.type_hash, peer.node_fqn
        )

    def _check(
        self, topic: str, our_type: str, our_hash: str, type_name: str, type_hash: str, node: str
    ) -> None:
        if (our_type, our_hash) == (type_name, type_hash):
            return
        if our_type != type_name:
            fix = (
                f"; pass cmd_vel_type={_STAMPED!r}"
                if type_name.endswith("TwistStamped_")
                else f"; pass cmd_vel_type={_TWIST!r}"
                if type_name.endswith("::Twist_")
                else ""
            )
            raise ConfigurationError(
                f"robot {self._robot_id}: {node} uses {topic} as {type_name} ({type_hash}), "
                f"RosDiffDrive as {our_type} ({our_hash}){fix}"
            )
        raise ConfigurationError(
            f"robot {self._robot_id}: {node} uses {topic} as {type_name} with type hash "
            f"{type_hash}, ours ({self._link.distro}) is {our_hash}: the robot runs another ROS 2 "
            f"distribution or another definition of the message (RosLink(distro=...))"
        )

    def close(self) -> None:
        """Tells the robot to stop, withdraws the topics; idempotent."""
        publisher, self._publisher = self._publisher, None
        odometry, self._odometry = self._odometry, None
        if publisher is not None:
            try:
                self._command(publisher, 0.0, 0.0)
            finally:
                publisher.close()
        if odometry is not None:
            odometry.close()

    async def __aenter__(self) -> RosDiffDrive:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.close()

    # -- Middleware --------------------------------------------------------------------

    @property
    def robot_id(self) -> RobotId:
        return self._robot_id

    @property
    def speed_profile(self) -> SpeedProfile:
        return self._profile

    @speed_profile.setter
    def speed_profile(self, profile: SpeedProfile) -> None:
        self._profile = profile

    def pose(self) -> Pose:
        """The pose of the last odometry message, in the layers' frame.

        Raises:
            RobotStateError: not started (no odometry yet).
        """
        odometry = self._odometry
        if odometry is None or odometry.latest is None or self._pose is None:
            raise RobotStateError(
                f"robot {self._robot_id}: no odometry yet (start RosDiffDrive first)"
            )
        with contextlib.suppress(SimulationError):  # counted when taken: the last good one stands
            self._pose = self._world(odometry.latest)
        return self._pose

    async def move_to(self, x: float, y: float) -> Pose:
        start = self.pose()
        profile = self._profile
        controller = self._controller
        turn = abs(math.remainder(start.bearing_to(x, y) - start.heading, math.tau))
        distance = start.distance_to(x, y)
        expected = turn / controller.tuning.max_turn_rate + (
            profile.time_for(distance) if distance > 0 else 0.0
        )
        clock = self._clock
        driving: list[float] = []  # when it started driving (after the first turn)

        def step(pose: Pose) -> tuple[float, float] | None:
            cruise = profile.speed_at(clock.now() - driving[0] if driving else 0.0)
            velocity = controller.toward(pose, x, y, cruise)
            if velocity is not None and not controller.turning and not driving:
                driving.append(clock.now())
            return velocity

        pose = await self._control(f"move_to({x:.3f}, {y:.3f})", expected, step)
        if self._profile is profile and driving:
            self._profile = profile.advanced(clock.now() - driving[0])
        return pose

    async def rotate_to(self, heading: float) -> Pose:
        start = self.pose()
        turn = abs(math.remainder(heading - start.heading, math.tau))
        controller = self._controller
        return await self._control(
            f"rotate_to({heading:.3f})",
            turn / controller.tuning.max_turn_rate,
            lambda pose: controller.facing(pose, heading),
        )

    async def robots_within(self, radius: float) -> Positions:
        # Odometry knows nothing of other robots; a real deployment asks its lidar or
        # the swarm's localisation, and the layers learn positions from messages.
        return _nobody()

    # -- the control loop --------------------------------------------------------------

    async def _control(
        self, what: str, expected: float, command: Callable[[Pose], tuple[float, float] | None]
    ) -> Pose:
        publisher = self._publisher
        if publisher is None or self._odometry is None:
            raise RobotStateError(f"robot {self._robot_id}: start RosDiffDrive before {what}")
        if self._moving:
            raise RobotStateError(
                f"robot {self._robot_id} is already moving: await or cancel that move first"
            )
        self._moving = True
        self._controller.reset()
        limit = self._move_timeout if self._move_timeout is not None else 3.0 * expected + 5.0
        began = self._clock.now()
        try:
            while True:
                pose = await self._next_odometry(what)
                velocity = command(pose)
                if velocity is None:
                    return pose
                if self._clock.now() - began > limit:
                    raise RosTimeout(
                        f"robot {self._robot_id}: {what} not done within {limit:.1f} s; at "
                        f"({pose.x:.3f}, {pose.y:.3f}, heading {pose.heading:.3f})"
                    )
                self._command(publisher, *velocity)
        finally:
            self._moving = False
            self._command(publisher, 0.0, 0.0)

    async def _next_odometry(self, what: str) -> Pose:
        odometry = self._odometry
        if odometry is None:
            raise RobotStateError(f"robot {self._robot_id}: RosDiffDrive is closed")
        try:
            async with self._clock.timeout(self._odom_timeout):
                while True:
                    message = await odometry.receive()
                    while odometry.clear():  # act on the newest pose, not a backlog
                        message = odometry.latest or message
                    try:
                        self._pose = self._world(message)
                    except SimulationError as exc:  # finite, yet no pose: the next one
                        odometry.drop("unusable_pose", str(exc))
                        continue
                    return self._pose
        except TimeoutError:
            raise RosTimeout(
                f"robot {self._robot_id}: no odometry on {odometry.topic} for "
                f"{self._odom_timeout:g} s ({what}); is the robot's driver running?"
            ) from None

    def _world(self, odometry: dict[str, Any]) -> Pose:
        pose = odometry["pose"]["pose"]
        position, q = pose["position"], pose["orientation"]
        yaw = math.atan2(
            2.0 * (q["w"] * q["z"] + q["x"] * q["y"]), 1.0 - 2.0 * (q["y"] ** 2 + q["z"] ** 2)
        )
        o = self._origin
        cos, sin = math.cos(o.heading), math.sin(o.heading)
        x, y = position["x"], position["y"]
        return Pose(o.x + cos * x - sin * y, o.y + sin * x + cos * y, yaw + o.heading)

    def _command(self, publisher: RosPublisher, speed: float, turn: float) -> None:
        twist = {"linear": {"x": speed}, "angular": {"z": turn}}
        if self._cmd_vel_type == _STAMPED:
            ns = self._link.clock_ns()
            stamp = {"sec": ns // 10**9, "nanosec": ns % 10**9}
            publisher.publish({"header": {"stamp": stamp, "frame_id": "base_link"}, "twist": twist})
        else:
            publisher.publish(twist)

    def __repr__(self) -> str:
        cmd_vel, odom = self._topics
        return f"RosDiffDrive(robot_id={self._robot_id}, {cmd_vel} -> {odom}, {self._link!r})"
