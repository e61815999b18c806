"""A stand-in for a real robot's driver: a :class:`~cas_async.Middleware` that is not the simulator.

A hardware middleware turns each command into orders for the motor controller and
returns when the robot reports the motion done; it knows the robot's pose from
odometry or a localisation system. :class:`StubDriver` has no motors: it logs each
command, takes as long as the robot would (on the robot's clock), and knows its
pose by dead reckoning, i.e. where its commands should have taken it. It imports
nothing from ``cas_async.sim``: the layers above cannot tell the difference.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Final, final

import numpy as np

from cas_async import (
    Clock,
    ConfigurationError,
    Middleware,
    Pose,
    Positions,
    RobotId,
    RobotStateError,
    SpeedProfile,
)

__all__ = ["StubDriver"]

_log = logging.getLogger("examples.operational.driver")


def _nobody() -> Positions:
    ids, xy = np.empty(0, dtype=np.int64), np.empty((0, 2), dtype=np.float64)
    ids.flags.writeable = xy.flags.writeable = False
    return Positions(ids, xy)


_NOBODY: Final = _nobody()


@dataclass(frozen=True, slots=True)
class _Motion:
    """One command under way: turn at the turn rate, then drive straight under a profile."""

    start: Pose
    since: float  # clock instant the command started
    turn: float  # signed radians to turn first
    turn_time: float
    heading: float  # the heading after the turn
    distance: float  # metres to drive after the turn
    profile: SpeedProfile
    drive_time: float

    @property
    def duration(self) -> float:
        return self.turn_time + self.drive_time

    def pose_after(self, elapsed: float) -> Pose:
        """Where dead reckoning puts the robot ``elapsed`` seconds into the command."""
        start = self.start
        if elapsed < self.turn_time:
            return Pose(start.x, start.y, start.heading + self.turn * elapsed / self.turn_time)
        driven = min(self.profile.distance(elapsed - self.turn_time), self.distance)
        return Pose(
            start.x + driven * math.cos(self.heading),
            start.y + driven * math.sin(self.heading),
            self.heading,
        )


@final
class StubDriver(Middleware):
    """Logs every command and answers from its own dead-reckoned pose.

    Args:
        robot_id: the robot driven.
        start: the pose the robot starts in (from its localisation, on a real robot).
        clock: the robot's clock (pass the same one to the ``Robot``).
        speed_profile: the profile of the first translation.
        turn_rate: radians per second of every turn (``inf``: turns take no time).

    Raises:
        ConfigurationError: ``turn_rate`` is not > 0.
    """

    def __init__(
        self,
        robot_id: RobotId,
        start: Pose,
        clock: Clock,
        *,
        speed_profile: SpeedProfile,
        turn_rate: float = math.pi,
    ) -> None:
        if not turn_rate > 0:
            raise ConfigurationError(f"turn_rate must be > 0 rad/s, got {turn_rate!r}")
        self._robot_id = robot_id
        self._pose = start
        self._clock = clock
        self._profile = speed_profile
        self._turn_rate = turn_rate
        self._motion: _Motion | None = None

    @property
    def robot_id(self) -> RobotId:
        return self._robot_id

    @property
    def speed_profile(self) -> SpeedProfile:
        return self._profile

    @speed_profile.setter
    def speed_profile(self, profile: SpeedProfile) -> None:
        _log.info("robot %s driver: speed_profile = %r", self._robot_id, profile)
        self._profile = profile

    def pose(self) -> Pose:
        motion = self._motion
        if motion is None:
            return self._pose
        return motion.pose_after(self._clock.now() - motion.since)

    async def move_to(self, x: float, y: float) -> Pose:
        start = self.pose()
        heading = start.bearing_to(x, y)
        distance = start.distance_to(x, y)
        _log.info(
            "robot %s driver: move_to(%.6f, %.6f) from (%.3f, %.3f): %.3f m",
            self._robot_id,
            x,
            y,
            start.x,
            start.y,
            distance,
        )
        end = await self._perform(start, heading, distance)
        # Arrived: the pose is the command's target, not the rounding of its path.
        self._pose = Pose(x, y, end.heading)
        return self._pose

    async def rotate_to(self, heading: float) -> Pose:
        start = self.pose()
        _log.info("robot %s driver: rotate_to(%.6f)", self._robot_id, heading)
        return await self._perform(start, heading, 0.0)

    async def robots_within(self, radius: float) -> Positions:
        # This stub has no sensors: it sees no one (a real driver would ask its lidar,
        # or the swarm's localisation service).
        _log.info("robot %s driver: robots_within(%.3f)", self._robot_id, radius)
        return _NOBODY

    async def _perform(self, start: Pose, heading: float, distance: float) -> Pose:
        if self._motion is not None:
            raise RobotStateError(
                f"robot {self._robot_id} is already moving: await or cancel that move first"
            )
        turn = math.remainder(heading - start.heading, math.tau)
        profile = self._profile
        motion = _Motion(
            start=start,
            since=self._clock.now(),
            turn=turn,
            turn_time=abs(turn) / self._turn_rate,
            heading=heading,
            distance=distance,
            profile=profile,
            drive_time=profile.time_for(distance) if distance > 0 else 0.0,
        )
        self._motion = motion
        try:
            await self._clock.sleep_until(motion.since + motion.duration)
        except BaseException:
            # Cancelled mid-command: a real driver would order a stop; the robot
            # stays where it is at this instant.
            self._pose = self.pose()
            _log.info(
                "robot %s driver: stopped at (%.3f, %.3f)",
                self._robot_id,
                self._pose.x,
                self._pose.y,
            )
            raise
        finally:
            self._motion = None
        self._pose = end = motion.pose_after(motion.duration)
        if motion.drive_time > 0 and self._profile is profile:
            self._profile = profile.advanced(motion.drive_time)
        _log.info("robot %s driver: at (%.3f, %.3f)", self._robot_id, end.x, end.y)
        return end

    def __repr__(self) -> str:
        pose = self.pose()
        return f"StubDriver(robot_id={self._robot_id}, at ({pose.x:.3f}, {pose.y:.3f}))"
