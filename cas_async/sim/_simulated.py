"""The simulated middleware and hands: kinematics and items in an :class:`Environment`.

:class:`SimulatedMiddleware` implements :class:`~cas_async.Middleware` with
closed-form kinematics, an :class:`~cas_async.sim.Environment` and the robot's
clock; :class:`SimulatedHands` implements :class:`~cas_async.Hands` with the
Environment's item ledger. A hardware implementation plugs in at the same place
without changing any layer.

The speed profile is how an application shapes motion without the middleware
knowing why: fatigue, for instance, is ``speed_profile = Decelerating(...)``
when a load is picked up and ``speed_profile = ConstantSpeed(...)`` when it is
handed over. The profile ages with the time spent translating, so its state
carries across moves until it is replaced.
"""

from __future__ import annotations

import contextlib
import math
from typing import final

from .._body._middleware import Hands, Middleware
from .._body._phases import check_phases
from .._body._pose import Pose
from .._body._positions import Positions
from .._body._profiles import SpeedProfile
from .._errors import RobotStateError, SimulationError, UnknownRobotError
from .._time._clock import Clock
from .._types import ItemId, RobotId
from ._environment import Environment
from ._kinematics import Motion, check_turn_rate

__all__ = ["SimulatedHands", "SimulatedMiddleware"]


@final
class SimulatedMiddleware(Middleware):
    """Moves a robot of an :class:`Environment` in simulated time.

    Each action plans a closed-form :class:`Motion` from the robot's pose at
    ``clock.now()``, registers it in the Environment, and sleeps until
    ``start + duration`` on the clock: an absolute deadline, so rounding does not
    accumulate over a sequence of moves. Works on scaled real time and on
    virtual time alike.

    Args:
        environment: the world the robot is in.
        robot_id: the robot, already added to ``environment``.
        clock: the robot's clock (the layer's ``self.clock``).
        turn_rate: radians per second for rotations (``inf``: instant).
        speed_profile: the profile of the first translation.

    Raises:
        UnknownRobotError: ``robot_id`` is not in ``environment``.
        SimulationError: ``turn_rate`` is not positive, or the profile is invalid.
    """

    def __init__(
        self,
        environment: Environment,
        robot_id: RobotId,
        clock: Clock,
        *,
        turn_rate: float,
        speed_profile: SpeedProfile,
    ) -> None:
        environment.is_mobile(robot_id)  # raises UnknownRobotError early
        self._environment = environment
        self._robot_id = robot_id
        self._clock = clock
        self._turn_rate = check_turn_rate(turn_rate)
        self.speed_profile = speed_profile
        self._busy = False
        # The instant the last action settled. A timer may wake a hair before its
        # deadline; the next action must still not start before the last one ended.
        self._settled = -math.inf

    @property
    def robot_id(self) -> RobotId:
        """The robot this middleware drives."""
        return self._robot_id

    @property
    def turn_rate(self) -> float:
        """Radians per second of every rotation."""
        return self._turn_rate

    @property
    def speed_profile(self) -> SpeedProfile:
        """The profile the next translation follows (aged by past translations)."""
        return self._profile

    @speed_profile.setter
    def speed_profile(self, profile: SpeedProfile) -> None:
        if not isinstance(profile, SpeedProfile):
            raise SimulationError(f"speed_profile must be a SpeedProfile, got {profile!r}")
        check_phases(profile.phases())
        self._profile = profile

    def pose(self) -> Pose:
        """The robot's exact pose at ``clock.now()``."""
        return self._environment.pose_at(self._robot_id, self._clock.now())

    def _start_time(self) -> float:
        return max(self._clock.now(), self._settled)

    async def move_to(self, x: float, y: float) -> Pose:
        """Turns to face ``(x, y)``, drives there under the speed profile, returns the end pose.

        Raises:
            SimulationError: the target is not finite, or the robot is immobile
                and the target is not where it stands.
            RobotStateError: another move of this robot is under way.
        """
        start = self._start_time()
        here = self._environment.pose_at(self._robot_id, start)
        motion = Motion.straight_to(here, x, y, turn_rate=self._turn_rate, profile=self._profile)
        return await self._perform(motion, start)

    async def rotate_to(self, heading: float) -> Pose:
        """Turns in place, the short way round, to ``heading``; returns the end pose.

        Raises:
            SimulationError: ``heading`` is not finite, or the robot is immobile.
            RobotStateError: another move of this robot is under way.
        """
        start = self._start_time()
        here = self._environment.pose_at(self._robot_id, start)
        motion = Motion.turn_to(here, heading, turn_rate=self._turn_rate)
        return await self._perform(motion, start)

    async def robots_within(self, radius: float) -> Positions:
        """The other robots within ``radius`` (inclusive) at ``clock.now()``, nearest first."""
        return self._environment.within(self._robot_id, radius, self._clock.now())

    async def _perform(self, motion: Motion, start: float) -> Pose:
        if self._busy:
            raise RobotStateError(
                f"robot {self._robot_id} is already moving: await or cancel that move first"
            )
        self._environment.start_motion(self._robot_id, motion, start)
        self._busy = True
        end = start + motion.duration
        profile = self._profile
        try:
            await self._clock.sleep_until(end)
        except BaseException:
            # Cancelled (or interrupted) mid-move: the robot stops where it is now.
            # A robot taken out of the environment meanwhile has nothing to stop, and
            # that must not replace the cancellation being re-raised.
            with contextlib.suppress(UnknownRobotError):
                stop = min(max(self._clock.now(), start), end)
                self._settle(stop)
                self._age(profile, motion.translating_time(stop - start))
            raise
        finally:
            self._busy = False
        # Settle at the planned end instant, not at now(): the pose is then exactly
        # the motion's end, whatever the timer's rounding or lateness.
        self._settle(end)
        self._age(profile, motion.translation_time)
        return motion.end

    def _settle(self, t: float) -> None:
        self._environment.halt(self._robot_id, t)
        self._settled = t

    def _age(self, used: SpeedProfile, translating: float) -> None:
        # If the application replaced the profile during the move, its choice wins.
        if self._profile is used and translating > 0:
            self._profile = used.advanced(translating)

    def __repr__(self) -> str:
        return (
            f"SimulatedMiddleware(robot_id={self._robot_id}, turn_rate={self._turn_rate:g}, "
            f"speed_profile={self._profile!r})"
        )


@final
class SimulatedHands(Hands):
    """A robot's hands in an :class:`Environment`: its items, in the Environment's ledger.

    Every operation happens at ``clock.now()``. Without a latency each completes
    before it returns (nothing is awaited inside), so a hand-over is atomic in the
    simulation too; with the Environment's latency, a hand-over returns when the
    receiver's answer is back (see :meth:`Environment.send_item`). A gripper's
    time to grasp or release is the robotic layer's to wait for, on its clock,
    around the call.

    Args:
        environment: the world the robot is in.
        robot_id: the robot, already added to ``environment``.
        clock: the robot's clock.
        reach: the largest distance from this robot at which it can hand an item
            over (the default allows only robots at the same spot, up to rounding).

    Raises:
        UnknownRobotError: ``robot_id`` is not in ``environment``.
        SimulationError: ``reach`` is negative or not finite.
    """

    def __init__(
        self, environment: Environment, robot_id: RobotId, clock: Clock, *, reach: float = 1e-6
    ) -> None:
        environment.is_mobile(robot_id)  # raises UnknownRobotError early
        if not (math.isfinite(reach) and reach >= 0):
            raise SimulationError(f"reach must be a finite number >= 0, got {reach!r}")
        self._environment = environment
        self._robot_id = robot_id
        self._clock = clock
        self._reach = float(reach)

    @property
    def robot_id(self) -> RobotId:
        """The robot these hands belong to."""
        return self._robot_id

    @property
    def reach(self) -> float:
        """The largest distance at which this robot hands an item over."""
        return self._reach

    async def items(self) -> tuple[ItemId, ...]:
        """The items the robot holds now, in the order it received them."""
        return self._environment.items.held_by(self._robot_id)

    async def accept_from(self, giver: RobotId) -> None:
        """Takes items from ``giver`` from now on (see :meth:`Environment.accept_from`)."""
        self._environment.accept_from(self._robot_id, giver)

    async def refuse_from(self, giver: RobotId) -> None:
        """Takes no more items from ``giver`` (see :meth:`Environment.refuse_from`)."""
        self._environment.refuse_from(self._robot_id, giver)

    async def create_item(self) -> ItemId:
        """Creates an item in the robot's hands at ``clock.now()`` and returns its id."""
        return self._environment.create_item(self._robot_id, self._clock.now())

    async def hand_over(self, item: ItemId, receiver: RobotId) -> None:
        """Gives ``item`` to ``receiver`` at ``clock.now()``: the one moment it changes hands.

        Allowed during a move too: the positions are exact at that instant. Over
        the Environment's latency, if it has one, the item arrives later and the
        receiver's answer comes back later still (see :meth:`Environment.send_item`).

        Raises:
            UnknownRobotError: ``receiver`` is not in the environment.
            SimulationError: the robots are farther apart than :attr:`reach`, this
                robot does not hold ``item``, ``receiver`` is this robot, or its
                hands are not held out to this robot.
        """
        await self._environment.send_item(
            item, self._robot_id, receiver, self._clock.now(), reach=self._reach
        )

    async def retire_item(self, item: ItemId) -> None:
        """Retires ``item`` at ``clock.now()``.

        Raises:
            SimulationError: this robot does not hold ``item``.
        """
        self._environment.retire_item(item, self._robot_id, self._clock.now())

    def __repr__(self) -> str:
        return f"SimulatedHands(robot_id={self._robot_id}, reach={self._reach:g})"
