"""wake_after(): timers that run inner_process() again without blocking the layer."""

from __future__ import annotations

import asyncio
import gc

import cas_async
from cas_async import MemoryTransport, Robot, Swarm, VirtualClock
from cas_async.testing import wait_all_tasks_blocked
from tests.stacks import STACK_MESSAGES, Query, Recorder


class Ticker(Recorder):
    """Asks to be woken twice (two keys); notes when inner_process runs and messages come."""

    def __init__(self) -> None:
        super().__init__()
        self.runs: list[float] = []
        self.handled: list[float] = []

    async def inner_process(self) -> None:
        await super().inner_process()
        self.runs.append(self.clock.now())
        if self.inner_calls == 1:
            self.wake_after(10.0, "first")
            self.wake_after(25.0, "second")

    async def handle_msg(self, msg: object) -> None:
        self.handled.append(self.clock.now())
        await super().handle_msg(msg)  # type: ignore[arg-type]


def test_wakes_at_the_times_asked_and_messages_are_not_held_up() -> None:
    async def main() -> tuple[list[float], list[float]]:
        clock, transport = VirtualClock(), MemoryTransport()
        ticker, other = Ticker(), Recorder()
        robots = [
            Robot(1, [ticker], clock=clock, transport=transport, messages=STACK_MESSAGES),
            Robot(2, [other], clock=clock, transport=transport, messages=STACK_MESSAGES),
        ]
        async with Swarm(robots):
            await clock.sleep(3.0)
            other.send(1, Query(1))  # handled at once, not after the 10 s timer
            await clock.sleep(30.0)
        return ticker.runs, ticker.handled

    runs, handled = cas_async.run(main(), virtual=True)
    assert handled == [3.0]
    assert runs == [0.0, 3.0, 10.0, 25.0]  # start, after the message, the two timers


def test_pending_wakes_are_cancelled_when_the_robot_stops() -> None:
    async def main() -> int:
        ticker = Ticker()
        robot = Robot(1, [ticker], clock=VirtualClock(), messages=STACK_MESSAGES)
        loop = asyncio.get_running_loop()
        assert isinstance(loop, cas_async.VirtualTimeLoop)
        async with robot:
            await wait_all_tasks_blocked()
            assert len(loop.timer_deadlines()) == 2
        return len(loop.timer_deadlines())

    assert cas_async.run(main(), virtual=True) == 0


class Repeater(Recorder):
    """Wakes itself every simulated second, ``times`` times."""

    def __init__(self, times: int) -> None:
        super().__init__()
        self.left = times

    async def inner_process(self) -> None:
        if self.left:
            self.left -= 1
            self.wake_after(1.0)


def test_fired_wakes_leave_no_garbage_for_the_cycle_collector() -> None:
    # A timer's callback and its handle must not refer to each other once it has
    # gone off: 10,000 robots waking every second would otherwise leave cycles that
    # only full garbage collections free (measured: a third of a 2,500-robot run).
    async def main() -> int:
        repeater = Repeater(500)
        robot = Robot(1, [repeater], clock=VirtualClock(), messages=STACK_MESSAGES)
        async with robot:
            gc.collect()
            gc.disable()
            try:
                await robot.clock.sleep(600.0)
                assert repeater.left == 0
                return gc.collect()
            finally:
                gc.enable()

    assert cas_async.run(main(), virtual=True) < 100
