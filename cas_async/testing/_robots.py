"""Robots a test starts, stopped and checked (failures, drops) when the test ends."""

from __future__ import annotations

import asyncio
from collections import Counter
from collections.abc import Collection, Iterable, Sequence
from contextlib import AsyncExitStack
from typing import Any, final

from .. import Clock, Layer, Message, Robot, Swarm, Transport, VirtualClock, VirtualTimeLoop

__all__ = ["Robots", "UnexpectedDrops", "default_clock"]


class UnexpectedDrops(AssertionError):
    """Robots of a test dropped messages for reasons the test did not allow."""


def default_clock(clock: Clock | None) -> Clock | None:
    """``clock``, or on the virtual-time loop a :class:`~cas_async.VirtualClock`."""
    if clock is None and isinstance(asyncio.get_running_loop(), VirtualTimeLoop):
        return VirtualClock()
    return clock


@final
class Robots:
    """Starts robots and swarms for a test; :meth:`aclose` stops them and checks them.

    Args:
        allowed_drops: drop reasons that are no failure (``robot.dropped``); any
            other makes :meth:`aclose` raise :class:`UnexpectedDrops`.
        messages: the messages of robots started without ``messages=`` (default:
            every registered message).
    """

    def __init__(
        self,
        *,
        allowed_drops: Collection[str] = (),
        messages: Sequence[type[Message]] | None = None,
    ) -> None:
        self.allowed_drops = set(allowed_drops)
        self._messages = messages
        self._stack = AsyncExitStack()
        self._robots: list[Robot] = []

    async def start(
        self,
        robot_id: int,
        layers: Sequence[Layer],
        *,
        transport: Transport | None = None,
        clock: Clock | None = None,
        **options: Any,
    ) -> Robot:
        """Makes and starts a robot (see :class:`~cas_async.Robot`); stopped by :meth:`aclose`.

        On the virtual-time loop the clock defaults to a :class:`~cas_async.VirtualClock`.
        """
        clock = default_clock(clock)
        if self._messages is not None:
            options.setdefault("messages", self._messages)
        robot = Robot(robot_id, layers, transport=transport, clock=clock, **options)
        await self._stack.enter_async_context(robot)
        self._robots.append(robot)
        return robot

    async def swarm(self, robots: Iterable[Robot]) -> Swarm:
        """Starts ``robots`` (made, not started) as one swarm; stopped by :meth:`aclose`."""
        members = list(robots)
        swarm = await self._stack.enter_async_context(Swarm(members))
        self._robots.extend(members)
        return swarm

    @property
    def robots(self) -> tuple[Robot, ...]:
        """The robots started so far, in order."""
        return tuple(self._robots)

    def drops(self) -> dict[int, dict[str, int]]:
        """What each robot dropped so far, by reason (robots that dropped nothing left out)."""
        return {robot.robot_id: dict(robot.dropped) for robot in self._robots if robot.dropped}

    async def aclose(self) -> None:
        """Stops and closes every robot, the last started first.

        Raises:
            ~cas_async.LayerError: a layer of a robot failed (the first such failure).
            UnexpectedDrops: a robot dropped a message for a reason not allowed.
        """
        await self._stack.aclose()  # raises a robot's LayerError
        unexpected = {
            robot_id: {r: n for r, n in reasons.items() if r not in self.allowed_drops}
            for robot_id, reasons in self.drops().items()
        }
        unexpected = {robot_id: reasons for robot_id, reasons in unexpected.items() if reasons}
        if unexpected:
            total: Counter[str] = Counter()
            for reasons in unexpected.values():
                total.update(reasons)
            lines = [f"robot {rid}: {reasons}" for rid, reasons in sorted(unexpected.items())]
            raise UnexpectedDrops(
                f"robots dropped messages ({dict(total)}); allow a reason with "
                "cas_robots.allowed_drops.add(reason) if the test expects it:\n  "
                + "\n  ".join(lines)
            )
