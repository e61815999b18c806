"""The gripper: what the Action layer asks of the robot's arms and object sensors.

:class:`Gripper` is the seam (as :class:`~cas_async.Middleware` is for motion):
a real robot implements it with its arms and camera, the simulation with the
:class:`~apps.box_moving.floor.Floor` (:class:`FloorGripper`). Every operation
is awaitable and happens at once; the time a lift or put-down takes is the
Action layer's to wait for, on its clock, around the call.
"""

from __future__ import annotations

from typing import Protocol, final

from cas_async import Clock

from .floor import Floor
from .messages import Side
from .records import Box

__all__ = ["FloorGripper", "Gripper"]


class Gripper(Protocol):
    """One robot's arms and object sensors."""

    async def scan(self) -> list[Box]:
        """The objects free to take: not moved, not lifted, not marked by another robot."""

    async def moved(self) -> int:
        """How many objects lie moved in the destination zone."""

    async def claim(self, obj: int) -> None:
        """Marks ``obj`` as this robot's selection (other robots' scans leave it out)."""

    async def unclaim(self, obj: int) -> None:
        """Takes this robot's mark off ``obj``."""

    async def lift(self, obj: int, side: Side, partner: int | None) -> None:
        """Lifts ``obj`` from ``side``; ``partner`` lifts it too (``None``: alone)."""

    async def put_down(self, obj: int) -> None:
        """Puts ``obj`` down where it is."""


@final
class FloorGripper:
    """A :class:`Gripper` on the simulated :class:`~.floor.Floor`, acting at ``clock.now()``.

    Args:
        floor: the objects.
        robot_id: the robot whose arms these are.
        clock: the robot's clock.
    """

    def __init__(self, floor: Floor, robot_id: int, clock: Clock) -> None:
        self._floor = floor
        self._robot_id = robot_id
        self._clock = clock

    async def scan(self) -> list[Box]:
        """The free objects, as they lie now."""
        return self._floor.free(self._robot_id)

    async def moved(self) -> int:
        """Objects moved so far."""
        return self._floor.moved

    async def claim(self, obj: int) -> None:
        """Marks ``obj`` (see :meth:`Floor.claim`)."""
        self._floor.claim(self._robot_id, obj, self._clock.now())

    async def unclaim(self, obj: int) -> None:
        """Unmarks ``obj`` (see :meth:`Floor.unclaim`)."""
        self._floor.unclaim(self._robot_id, obj, self._clock.now())

    async def lift(self, obj: int, side: Side, partner: int | None) -> None:
        """Lifts ``obj`` (see :meth:`Floor.lift`)."""
        self._floor.lift(self._robot_id, obj, side, partner, self._clock.now())

    async def put_down(self, obj: int) -> None:
        """Puts ``obj`` down (see :meth:`Floor.put_down`)."""
        self._floor.put_down(self._robot_id, obj, self._clock.now())

    def __repr__(self) -> str:
        return f"FloorGripper(robot_id={self._robot_id})"
