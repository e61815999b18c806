"""The gathering's objective, ``Gathered``: when the mission is done, and what it measured."""

from __future__ import annotations

import math
from collections.abc import Mapping

from cas_async import RobotId, SimulationError
from cas_async.scenario import Objective, RunResult, Tally, Watch
from cas_async.sim import Motion

from .plan import Point, centroid

__all__ = ["Gathered"]


class Gathered(Objective):
    """Every robot stands within ``radius`` of the meeting point.

    The meeting point is the centroid of where the robots start: the point they
    agree on when each hears every other. A robot has gathered once a drive of
    its ends within ``radius`` of it (or if it starts there), and no longer has
    while it drives again. The objective watches the robots' motions in the
    Environment, so it knows the exact instant each stopped; it never asks a layer.

    Args:
        homes: where each robot starts.
        radius: how close to the meeting point a robot must stand.
        world: ``(width, height)`` of the area: no robot may leave it.
    """

    noun = "robot"
    verb = "gathered"
    detail = "moving"
    kind = "gathering"
    distributable = True  # it reads only the Environment: the run may go across processes

    def __init__(self, homes: Mapping[RobotId, Point], radius: float, world: Point) -> None:
        self.meeting_point = centroid(homes.values())
        self.radius = radius
        self.world = world
        self._robots = len(homes)
        self._arrivals = {robot: 0.0 for robot, home in homes.items() if self._near(home)}
        self._moving: set[RobotId] = set()
        self._watch: Watch | None = None
        self._done_at: float | None = None

    @property
    def target(self) -> int:
        """Every robot."""
        return self._robots

    def attach(self, watch: Watch) -> None:
        """Follows every motion that starts or ends in the Environment."""
        self._watch = watch
        watch.environment.watch_motions(self._moved)

    def _near(self, point: Point) -> bool:
        return math.dist(point, self.meeting_point) <= self.radius

    def _moved(self, robot: RobotId, motion: Motion, start: float) -> None:
        watch = self._watch
        if watch is None or self._done_at is not None:  # what comes after is not the run's
            return
        if motion.duration > 0:  # a drive begins
            self._moving.add(robot)
            self._arrivals.pop(robot, None)
        else:  # the robot stands still from ``start`` on
            self._moving.discard(robot)
            if self._near((motion.end.x, motion.end.y)):
                self._arrivals[robot] = start
        watch.changed(start)
        if len(self._arrivals) == self._robots:
            self._done_at = start
            watch.completed(start)

    def progress(self) -> Tally:
        """Robots gathered, and robots driving."""
        return Tally(len(self._arrivals), len(self._moving))

    def check(self) -> None:
        """No robot is outside the world."""
        if self._watch is None:
            return
        width, height = self.world
        positions = self._watch.environment.positions_at(self._watch.now())
        for robot, (x, y) in positions.as_dict().items():
            if not (0 <= x <= width and 0 <= y <= height):
                raise SimulationError(
                    f"robot {robot} left the world: it is at ({x:g}, {y:g}), "
                    f"outside 0..{width:g} x 0..{height:g}"
                )

    def measure(self, result: RunResult, end: float) -> None:
        """Robots gathered, when each arrived, the meeting point, and how close they stand."""
        times = sorted(self._arrivals.values())
        result.delivered = len(times)
        result.delivery_times = times
        result.samples["arrival_time"] = list(times)
        result.extra["meeting_x"] = self.meeting_point[0]
        result.extra["meeting_y"] = self.meeting_point[1]
        if self._watch is not None:
            xy = self._watch.environment.positions_at(end).xy
            result.extra["spread"] = max(math.dist(p, self.meeting_point) for p in xy.tolist())
