"""The middleware: what a robotic layer asks of its robot, simulated or real.

The thesis puts a (pseudo-)middleware between the robotic layers and the robot
(§3.1, Fig. 27): in operation it drives hardware, in simulation it computes
kinematics and consults the Environment. This module is that seam, and it
belongs to the core: a hardware robot implements it without importing the
simulator.

* :class:`Middleware` is what every robot must have: motion (``move_to``,
  ``rotate_to``, the ``speed_profile`` translations follow) and perception
  (``pose``, ``robots_within``).
* :class:`Hands` is optional: robots that carry items (buckets, boxes) hold,
  create, hand over and retire them. Every item operation is awaitable, because
  a gripper takes time to close, and a world served by another process answers
  later. A hand-over is still one atomic moment: before it the giver holds the
  item, after it the receiver does.

The simulated implementations are :class:`~cas_async.sim.SimulatedMiddleware`
and :class:`~cas_async.sim.SimulatedHands`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

from .._types import ItemId, RobotId
from ._pose import Pose
from ._positions import Positions
from ._profiles import SpeedProfile

__all__ = ["Hands", "Middleware"]


class Middleware(ABC):
    """One robot's motion and perception, as a robotic layer sees them.

    Moves are exclusive: a second move or rotation while one is under way raises
    :class:`~cas_async.RobotStateError`. Cancelling a move stops the robot where
    it is at that instant and re-raises the cancellation.
    """

    @property
    @abstractmethod
    def robot_id(self) -> RobotId:
        """The robot this middleware drives."""

    @property
    @abstractmethod
    def speed_profile(self) -> SpeedProfile:
        """The profile the next translation follows (aged by past translations)."""

    @speed_profile.setter
    @abstractmethod
    def speed_profile(self, profile: SpeedProfile) -> None:
        """Replaces the profile; a move under way keeps the one it started with."""

    @abstractmethod
    def pose(self) -> Pose:
        """The robot's pose now (during a move too)."""

    @abstractmethod
    async def move_to(self, x: float, y: float) -> Pose:
        """Turns to face ``(x, y)``, drives there, and returns the pose reached."""

    @abstractmethod
    async def rotate_to(self, heading: float) -> Pose:
        """Turns in place to ``heading`` (radians, counter-clockwise from +x), returns the pose."""

    @abstractmethod
    async def robots_within(self, radius: float) -> Positions:
        """The other robots within ``radius`` now, nearest first."""


class Hands(ABC):
    """What a robot that carries items does with them; every operation is awaitable.

    A robot takes items from anyone until it first calls :meth:`accept_from` or
    :meth:`refuse_from`; from then on only from the givers it accepts. Holding
    out one's hands is a physical act: a receiver that withdraws them and then
    finds no item in them knows that no hand-over from that giver can happen any
    more, whatever messages were lost.
    """

    @property
    @abstractmethod
    def robot_id(self) -> RobotId:
        """The robot these hands belong to."""

    @abstractmethod
    async def items(self) -> tuple[ItemId, ...]:
        """The items the robot holds now, in the order it received them."""

    @abstractmethod
    async def create_item(self) -> ItemId:
        """Creates an item in the robot's hands and returns its id."""

    @abstractmethod
    async def hand_over(self, item: ItemId, receiver: RobotId) -> None:
        """Gives ``item``, held by this robot, to robot ``receiver``.

        The one atomic moment an item changes hands: before it this robot holds
        the item, after a successful call ``receiver`` does, and a failed call
        leaves it where it was. The robots must be within reach, and the
        receiver's hands held out to this robot.
        """

    @abstractmethod
    async def retire_item(self, item: ItemId) -> None:
        """Retires ``item``, held by this robot: nobody holds it any more (delivered)."""

    @abstractmethod
    async def accept_from(self, giver: RobotId) -> None:
        """Holds out this robot's hands to ``giver``: from now on it takes items from it."""

    @abstractmethod
    async def refuse_from(self, giver: RobotId) -> None:
        """Withdraws this robot's hands from ``giver``: no hand-over from it can happen now."""
