"""``Swarm``: starts, runs and stops a set of robots together; robots join and leave it.

Robots started one by one could message a robot whose endpoint is not open yet.
A swarm opens every robot's endpoint first, then starts every robot's layers::

    async with Swarm(robots) as swarm:
        await swarm.run()      # until every robot's run() would return

While it runs, ``await swarm.add(robot)`` starts another robot and ``await
swarm.remove(robot_id)`` stops one; the others' transports tell their layers
(``on_robot_joined``/``on_robot_left``), a message to a robot that left is
dropped and counted (``unknown_robot``), and a request waiting on it fails with
:class:`~cas_async.RobotGone`.

When a robot fails, the others are stopped and ``run()`` raises its
:class:`~cas_async.LayerError`.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterable, Iterator
from typing import Any, final

from .._errors import ConfigurationError, RobotStateError, UnknownRobotError
from .._types import RobotId
from ._robot import Robot
from ._robot_state import RobotState

__all__ = ["Swarm"]


def _same_time(first: Robot, other: Robot) -> None:
    """Refuses robots whose clocks do not keep one time (see :class:`Swarm`)."""
    a, b = first.clock, other.clock
    if a is b or (type(a) is type(b) and a.time_factor == b.time_factor):
        return
    raise ConfigurationError(
        f"swarm: robot {first.robot_id} runs on {a!r} and robot {other.robot_id} on {b!r}; "
        "robots of one swarm share one simulated time: give them the same clock object"
    )


@final
class Swarm:
    """A set of robots with one lifecycle.

    Robots of a swarm share one simulated time: their clocks must be one clock
    object or clocks of the same kind and time factor (robots created without a
    clock each get ``ScaledClock(1.0)``, which is fine).

    Args:
        robots: the robots; their ids must be unique.

    Raises:
        ConfigurationError: two robots have one id, or clocks that keep different times.
    """

    def __init__(self, robots: Iterable[Robot]) -> None:
        self._robots: dict[RobotId, Robot] = {}
        self._running = False
        self._changed = asyncio.Event()  # a robot joined or left: run() looks again
        for robot in robots:
            self._admit(robot)

    def _admit(self, robot: Robot) -> None:
        if robot.robot_id in self._robots:
            raise ConfigurationError(f"swarm: two robots with id {robot.robot_id}")
        for first in self._robots.values():
            _same_time(first, robot)
            break
        self._robots[robot.robot_id] = robot

    def __iter__(self) -> Iterator[Robot]:
        return iter(list(self._robots.values()))

    def __len__(self) -> int:
        return len(self._robots)

    def __contains__(self, robot_id: object) -> bool:
        return robot_id in self._robots

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
        internal: dict[type[Any], int] = {}
        external: dict[type[Any], int] = {}
        for robot in self:
            robot.add_message_counts(internal, external)
        total: dict[str, dict[str, int]] = {"internal": {}, "external": {}}
        for kind, by_type in (("internal", internal), ("external", external)):
            into = total[kind]
            for cls, n in by_type.items():  # two classes may share a name
                into[cls.__name__] = into.get(cls.__name__, 0) + n
        return total

    def drop_counts(self) -> dict[str, int]:
        """Every robot's :attr:`Robot.dropped`, summed by reason."""
        total: dict[str, int] = {}
        for robot in self:
            for reason, n in robot.dropped.items():
                total[reason] = total.get(reason, 0) + n
        return total

    # -- lifecycle ---------------------------------------------------------------------

    async def __aenter__(self) -> Swarm:
        """Opens every robot's endpoint, then starts every robot's layers."""
        await self.open()
        self.start()
        return self

    async def open(self) -> None:
        """First half of ``async with``: opens every robot's endpoint (none runs yet).

        Between the halves, the robots can be reached but do nothing: a swarm spread
        over processes waits there until every process's robots can be reached.
        On failure, the endpoints opened are closed again.
        """
        opened: list[Robot] = []
        try:
            for robot in self:
                await robot.open()
                opened.append(robot)
        except BaseException:
            for robot in opened:
                robot.close()
            raise

    def start(self) -> None:
        """Second half of ``async with``: starts every robot's layers (see :meth:`open`)."""
        for robot in self:
            robot.start()
        self._running = True

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: object
    ) -> None:
        """Stops every robot, then closes every endpoint (the mirror of starting).

        No robot is closed while another still runs, so none sends to a robot that
        is gone. Raises the first layer failure that ``run()`` did not raise; the
        others are attached to it as notes.
        """
        try:
            await self.halt()
        finally:
            errors = self.close()
        if exc is not None:  # the block's own exception goes on, with ours noted on it
            for error in errors:
                exc.add_note(f"meanwhile {error}")
        elif errors:
            first, *others = errors
            for other in others:
                first.add_note(f"also {other}")
            raise first

    async def halt(self) -> None:
        """First half of stopping: stops every running robot and waits until its layers ended.

        The endpoints stay open (:meth:`close` is the second half), so no robot
        sends to one that is gone while the others stop.
        """
        self._running = False
        running = [robot for robot in self if robot.state is RobotState.RUNNING]
        for robot in running:
            robot.stop()
        await asyncio.gather(*(robot.halt() for robot in running))

    def close(self) -> list[BaseException]:
        """Second half of stopping: closes every robot's endpoint; returns the layer failures.

        Failures that ``run()`` did not raise, one per robot, first robot first:
        the caller raises them (``async with`` raises the first, the others noted).
        Robots opened but never started are closed too.
        """
        self._running = False
        for robot in self:
            robot.close()
        return [error for robot in self if (error := robot.take_failure()) is not None]

    # -- membership --------------------------------------------------------------------

    async def add(self, robot: Robot) -> None:
        """Adds ``robot``; in a running swarm it is opened and started at once.

        The robots already there learn that it joined from their transport.

        Raises:
            ConfigurationError: its id is taken, or its clock keeps another time.
        """
        self._admit(robot)
        if self._running:
            try:
                await robot.open()
            except BaseException:
                del self._robots[robot.robot_id]
                raise
            robot.start()
        self._changed.set()

    async def remove(self, robot_id: RobotId) -> Robot:
        """Takes robot ``robot_id`` out; a running one is stopped and closed, and returned.

        The others learn that it left from their transport: what they send it from
        now on is dropped and counted (``unknown_robot``), and requests waiting on
        it fail with :class:`~cas_async.RobotGone`.

        Raises:
            UnknownRobotError: no robot of this swarm has that id.
            LayerError: one of its layers had failed.
        """
        robot = self._robots.pop(robot_id, None)
        if robot is None:
            raise UnknownRobotError(f"swarm: no robot {robot_id} to remove")
        self._changed.set()
        if robot.state is RobotState.RUNNING:
            robot.stop()
            try:
                await robot.halt()
            finally:
                robot.close()
            failure = robot.take_failure()
            if failure is not None:
                raise failure
        elif robot.state is RobotState.OPEN:
            robot.close()
        return robot

    # -- running -----------------------------------------------------------------------

    async def run(self) -> None:
        """Waits until every robot's ``run()`` returns (robots added meanwhile included).

        Raises:
            LayerError: a robot failed; every robot was asked to stop.
            RobotStateError: the swarm was not started.
        """
        if not self._running:
            raise RobotStateError("swarm: start it with `async with swarm:` before run()")
        runs: dict[Robot, asyncio.Future[object]] = {}
        changed: asyncio.Future[object] = asyncio.get_running_loop().create_future()
        try:
            while True:
                for robot in self:
                    if robot not in runs and robot.state is RobotState.RUNNING:
                        runs[robot] = asyncio.ensure_future(robot.run())
                members = [runs[robot] for robot in self if robot in runs]
                for task in members:
                    if task.done() and task.exception() is not None:
                        await self._fail(runs)
                if all(task.done() for task in members):
                    return
                self._changed.clear()
                changed = asyncio.ensure_future(self._changed.wait())
                waits: list[asyncio.Future[object]] = [t for t in members if not t.done()]
                await asyncio.wait([*waits, changed], return_when=asyncio.FIRST_COMPLETED)
                changed.cancel()
        finally:
            changed.cancel()
            for task in runs.values():
                task.cancel()
            await asyncio.gather(*runs.values(), return_exceptions=True)

    async def _fail(self, runs: dict[Robot, asyncio.Future[object]]) -> None:
        """Stops every robot after one failed, then raises the first failure."""
        self.stop()
        await asyncio.wait(list(runs.values()))  # the others return once stopped
        for robot in self:
            task = runs.get(robot)
            error = None if task is None else task.exception()
            if error is not None:
                raise error

    def stop(self) -> None:
        """Asks every running robot to stop."""
        for robot in self:
            if robot.state is RobotState.RUNNING:
                robot.stop()
