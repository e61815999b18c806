"""``Swarm``: starts, runs and stops a set of robots together.

Robots started one by one could message a robot whose endpoint is not open yet.
A swarm opens every robot's endpoint first, then starts every robot's layers::

    async with Swarm(robots) as swarm:
        await swarm.run()      # until every robot's run() would return

When a robot fails, the others are stopped and ``run()`` raises its
:class:`~cas_async._errors.LayerError`.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterable, Iterator
from typing import final

from ._errors import ConfigurationError, RobotStateError
from ._robot import Robot
from ._robot_state import RobotState
from ._types import RobotId

__all__ = ["Swarm"]


@final
class Swarm:
    """A set of robots with one lifecycle.

    Args:
        robots: the robots; their ids must be unique.
    """

    def __init__(self, robots: Iterable[Robot]) -> None:
        self._robots: dict[RobotId, Robot] = {}
        for robot in robots:
            if robot.robot_id in self._robots:
                raise ConfigurationError(f"swarm: two robots with id {robot.robot_id}")
            self._robots[robot.robot_id] = robot

    def __iter__(self) -> Iterator[Robot]:
        return iter(self._robots.values())

    def __len__(self) -> int:
        return len(self._robots)

    def __getitem__(self, robot_id: RobotId) -> Robot:
        return self._robots[robot_id]

    def counters(self) -> dict[str, int]:
        """Every robot's counters, summed."""
        total: dict[str, int] = {}
        for robot in self:
            for name, value in robot.counters().items():
                total[name] = total.get(name, 0) + value
        return total

    def message_counts(self) -> dict[str, dict[str, int]]:
        """Every robot's :meth:`Robot.message_counts`, summed by class name."""
        total: dict[str, dict[str, int]] = {"internal": {}, "external": {}}
        for robot in self:
            for kind, counts in robot.message_counts().items():
                into = total[kind]
                for name, n in counts.items():
                    into[name] = into.get(name, 0) + n
        return total

    async def __aenter__(self) -> Swarm:
        """Opens every robot's endpoint, then starts every robot's layers."""
        opened: list[Robot] = []
        try:
            for robot in self:
                await robot.open()
                opened.append(robot)
        except BaseException:
            for robot in opened:
                robot.close()
            raise
        for robot in self:
            robot.start()
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: object
    ) -> None:
        """Stops every robot, then closes every endpoint (the mirror of starting).

        No robot is closed while another still runs, so none sends to a robot that
        is gone. Raises the first layer failure that ``run()`` did not raise; the
        others are attached to it as notes.
        """
        running = [robot for robot in self if robot.state is RobotState.RUNNING]
        for robot in running:
            robot.stop()
        try:
            await asyncio.gather(*(robot.halt() for robot in running))
        finally:
            for robot in running:
                robot.close()
        errors = [error for robot in running if (error := robot.take_failure()) is not None]
        if exc is not None:  # the block's own exception goes on, with ours noted on it
            for error in errors:
                exc.add_note(f"meanwhile {error}")
        elif errors:
            first, *others = errors
            for other in others:
                first.add_note(f"also {other}")
            raise first

    async def run(self) -> None:
        """Waits until every robot's ``run()`` returns.

        Raises:
            LayerError: a robot failed; every robot was asked to stop.
            RobotStateError: the swarm was not started.
        """
        if any(robot.state is not RobotState.RUNNING for robot in self):
            raise RobotStateError("swarm: start it with `async with swarm:` before run()")
        runs = [asyncio.ensure_future(robot.run()) for robot in self]
        try:
            done, _ = await asyncio.wait(runs, return_when=asyncio.FIRST_EXCEPTION)
            for task in done:
                error = task.exception()
                if error is not None:
                    self.stop()
                    await asyncio.wait(runs)  # the others return once stopped
                    raise error
        finally:
            for task in runs:
                task.cancel()
            await asyncio.gather(*runs, return_exceptions=True)

    def stop(self) -> None:
        """Asks every running robot to stop."""
        for robot in self:
            if robot.state is RobotState.RUNNING:
                robot.stop()
