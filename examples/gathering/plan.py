"""The top layer, ``Plan``: hear where everyone is, pick the meeting point, ask to go there."""

from __future__ import annotations

import math
from collections.abc import Collection, Hashable, Iterable
from typing import TypeAlias

from cas_async import Layer, Message, RobotId

from .messages import Arrived, DriveTo, Position

__all__ = ["Plan", "Point", "centroid"]

Point: TypeAlias = tuple[float, float]


def centroid(points: Iterable[Point]) -> Point:
    """The mean of ``points``.

    ``math.fsum`` is exactly rounded: every robot computes the very same float,
    whatever order it heard the positions in.
    """
    listed = list(points)
    n = len(listed)
    return math.fsum(x for x, _ in listed) / n, math.fsum(y for _, y in listed) / n


class Plan(Layer):
    """Tells the others where this robot is, picks the meeting point, asks ``Drive`` to go.

    The meeting point is the centroid of the positions heard, this robot's own
    included. The robot picks it as soon as it has heard every robot of ``team``,
    or, when ``patience`` runs out first, with the positions it has.

    Args:
        home: where this robot starts.
        team: every robot's id, this one's included.
        patience: simulated seconds to wait for every position.

    Attributes:
        heard: the positions heard so far, by robot (this robot's own included).
        meeting_point: where the robot drives, once picked.
        arrived: where the drive ended, once it has.
    """

    def __init__(self, home: Point, team: Collection[RobotId], patience: float) -> None:
        self.home = home
        self.team = frozenset(team)
        self.patience = patience
        self.heard: dict[RobotId, Point] = {}
        self.meeting_point: Point | None = None
        self.arrived: Point | None = None

    async def inner_process(self) -> None:
        if self.robot_id not in self.heard:  # at start: tell everyone, and start waiting
            self.heard[self.robot_id] = self.home
            self.broadcast(Position(*self.home))
            self.wake_after(self.patience, "patience")
        if self.meeting_point is None and self.heard.keys() >= self.team:
            await self._meet()

    async def handle_msg(self, msg: Message) -> None:
        match msg:
            case Position(x=x, y=y):
                self.heard[msg.robot_id] = (x, y)

    async def on_timer(self, key: Hashable) -> None:
        if key == "patience" and self.meeting_point is None:
            missing = sorted(self.team - self.heard.keys())
            self.log.info("no position from robots %s: meeting without them", missing)
            await self._meet()

    async def _meet(self) -> None:
        self.cancel_wake("patience")
        self.meeting_point = centroid(self.heard.values())
        # This layer's messages wait meanwhile; a drive takes as long as it takes.
        arrived = await self.request_down(
            DriveTo(*self.meeting_point), reply=Arrived, timeout=math.inf
        )
        self.arrived = (arrived.x, arrived.y)

    def termination_condition(self) -> bool:
        return self.arrived is not None
