"""The records of the Floor: the objects as placed, its events, its deliveries, its violations."""

from __future__ import annotations

import enum
from dataclasses import dataclass

from cas_async import SimulationError

from .geometry import Point

__all__ = ["Box", "Delivery", "FloorEvent", "FloorEventKind", "FloorViolation"]


class FloorViolation(SimulationError):
    """An operation or motion broke the Floor's invariant (see :mod:`.floor`).

    Attributes:
        robot: the robot at fault.
        obj: the object concerned.
        t: the simulated instant.
    """

    def __init__(self, problem: str, *, robot: int, obj: int, t: float) -> None:
        super().__init__(f"t={t:.6g}: robot {robot}, object {obj}: {problem}")
        self.robot, self.obj, self.t = robot, obj, t


@dataclass(frozen=True, slots=True)
class Box:
    """An object on the floor: its id, centre, weight, size and drop spot."""

    obj: int
    x: float
    y: float
    weight: float
    size: float
    drop_x: float
    drop_y: float

    @property
    def at(self) -> Point:
        """Its centre."""
        return (self.x, self.y)

    @property
    def drop(self) -> Point:
        """Its drop spot."""
        return (self.drop_x, self.drop_y)


class FloorEventKind(enum.StrEnum):
    """What happened to an object."""

    CLAIMED = "claimed"
    """A robot marked it as its selection."""
    UNCLAIMED = "unclaimed"
    """The robot took its mark off."""
    LIFTED = "lifted"
    """A robot lifted it (from one side)."""
    CARRIED = "carried"
    """Its lifters make a complete carry: it moves with them from now on."""
    PUT_DOWN = "put_down"
    """A robot put it down."""
    MOVED = "moved"
    """The last lifter put it down inside the destination zone: it counts as moved."""


@dataclass(frozen=True, slots=True)
class FloorEvent:
    """One event of the Floor: when, what, which object, which robots, and where it was."""

    t: float
    kind: FloorEventKind
    obj: int
    robots: tuple[int, ...]
    x: float
    y: float


@dataclass(frozen=True, slots=True)
class Delivery:
    """A moved object, as the objective measures it.

    Attributes:
        obj: the object.
        t: the instant it was moved (its last lifter put it down in the zone).
        selected: the instant it was last claimed (selected), else first lifted.
        carriers: the robots of its last carry.
        distance: the length of the path it travelled.
    """

    obj: int
    t: float
    selected: float
    carriers: tuple[int, ...]
    distance: float

    @property
    def joint(self) -> bool:
        """Whether two robots carried it."""
        return len(self.carriers) == 2
