"""What the Environment keeps per robot, and what it asks of another process's robots."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from .._errors import SimulationError
from .._types import ItemId, RobotId
from ._kinematics import Motion

__all__ = ["Courier", "RobotEntry", "check_instant"]


def check_instant(t: float) -> None:
    if math.isnan(t):
        raise SimulationError("t must be a number, got nan")


@dataclass(slots=True)
class RobotEntry:
    """One robot's entry: its current motion, since when, and its row in the table."""

    index: int
    mobile: bool
    motion: Motion
    since: float
    odometer: float = 0.0  # distance translated by the motions before the current one
    # Robots this one takes items from; None: from anyone (see Environment.accept_from).
    accepting: set[RobotId] | None = None
    local: bool = True  # its motions start here (else they are only seen, see see_motion)
    motions: int = 0  # motions started so far: their order within an instant
    sent: int = 0  # items sent so far, and answers given: their order within an instant
    seen: Motion | None = None  # with a latency: the motion the others see
    seen_since: float = -math.inf
    top_speed: float | None = None  # the fastest it may translate (None: unbounded)
    hidden: bool = False  # another process's robot this one does not watch (see hide)

    def travelled(self, t: float) -> float:
        """Total distance translated up to instant ``t``."""
        # A standing motion (the only kind that starts at -inf) translates nothing;
        # skipping it also avoids evaluating inf - inf.
        if self.motion.length == 0:
            return self.odometer
        return self.odometer + self.motion.travelled(t - self.since)


class Courier(Protocol):
    """Takes a hand-over's steps to robots of other processes (see ``Environment.set_local``)."""

    def arrive(
        self,
        at: float,
        item: ItemId,
        giver: RobotId,
        receiver: RobotId,
        sent: float,
        reach: float,
        n: int,
    ) -> None:
        """The item reaches ``receiver`` (another process's robot) at ``at``."""

    def receipt(
        self,
        at: float,
        item: ItemId,
        giver: RobotId,
        receiver: RobotId,
        n: int,
        refused: str | None,
        answer: int,
    ) -> None:
        """The answer to hand-over ``n`` reaches ``giver`` (another process's robot) at ``at``.

        ``answer`` is the receiver's own count of answers: their order within an instant.
        """
