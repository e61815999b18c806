"""``LearnedPlan``: the tutorial's Plan, but a policy says where to drive, one leg per step."""

from __future__ import annotations

import math
from collections.abc import Collection

from cas_async.rl import PolicyLayer
from examples.gathering.messages import Arrived, DriveTo, Position
from examples.gathering.plan import Plan, Point, centroid

__all__ = ["LearnedPlan"]


class LearnedPlan(PolicyLayer, Plan):
    """Tells the others where it starts, as ``Plan`` does; then drives where the policy says.

    The meeting point is what ``Plan`` would pick: the centroid of the positions
    heard (every robot's start, once all are heard). Instead of driving there, the
    robot drives one leg per step: the env's ``act`` turns the action it holds into
    the leg's end (or into staying put).

    Attributes:
        here: where the robot stands (its start, then where its last leg ended).
        step_start: where it stood when the current step began.
    """

    def __init__(self, home: Point, team: Collection[int], patience: float) -> None:
        super().__init__(home, team, patience)
        self.here: Point = home
        self.step_start: Point = home
        self._meeting: tuple[int, Point] | None = None  # (positions heard, their centroid)

    async def inner_process(self) -> None:
        if self.robot_id not in self.heard:  # at start: tell everyone where this robot is
            self.heard[self.robot_id] = self.home
            self.broadcast(Position(*self.home))

    async def on_action(self) -> None:
        """Drives the leg the action names, from where the robot stands (or stays)."""
        self.step_start = self.here
        target: Point = self.decide(self.here)  # act: where this step's leg ends
        if target == self.here:
            return
        arrived = await self.request_down(DriveTo(*target), reply=Arrived, timeout=math.inf)
        self.here = (arrived.x, arrived.y)

    @property
    def meeting(self) -> Point:
        """The centroid of the starts heard, its own included (before it starts: its own)."""
        if not self.heard:
            return self.home
        if self._meeting is None or self._meeting[0] != len(self.heard):  # heard more since
            self._meeting = (len(self.heard), centroid(self.heard.values()))
        return self._meeting[1]
