"""Scaled real time and virtual time."""

from __future__ import annotations

import asyncio
import random
import time

import pytest

import cas_async
from cas_async import (
    ConfigurationError,
    Layer,
    MemoryTransport,
    Message,
    RequestTimeout,
    Robot,
    ScaledClock,
    Swarm,
    VirtualClock,
    VirtualTimeLoop,
)
from tests.stacks import STACK_MESSAGES, Note, Query, Recorder

SIM_SECONDS = 1000.0


class Wanderer(Layer):
    """Sleeps random simulated intervals and messages random robots until SIM_SECONDS."""

    def __init__(self, seed: int, swarm: int, trace: list[tuple[float, int, str]]) -> None:
        self.rng = random.Random(seed)
        self.swarm = swarm
        self.trace = trace
        self.finished = False

    async def inner_process(self) -> None:
        if self.clock.now() > 0:
            return  # the walk below starts once, at start-up
        while self.clock.now() < SIM_SECONDS:
            await self.clock.sleep(self.rng.uniform(0.5, 3.0))
            target = self.rng.choice([r for r in range(self.swarm) if r != self.robot_id])
            self.send(target, Note(f"{self.robot_id}->{target}", [self.rng.randrange(100)]))
        self.finished = True

    async def handle_msg(self, msg: Message) -> None:
        self.trace.append((self.clock.now(), self.robot_id, f"{msg.text}:{msg.hops[0]}"))  # type: ignore[attr-defined]

    def termination_condition(self) -> bool:
        return self.finished


def simulate(seed: int, swarm: int = 10) -> list[tuple[float, int, str]]:
    trace: list[tuple[float, int, str]] = []

    async def main() -> None:
        transport, clock = MemoryTransport(), VirtualClock()
        robots = [
            Robot(
                i,
                [Wanderer(seed * 1000 + i, swarm, trace), Layer()],
                transport=transport,
                clock=clock,
                messages=STACK_MESSAGES,
            )
            for i in range(swarm)
        ]
        async with Swarm(robots) as running:
            await running.run()

    cas_async.run(main(), virtual=True)
    return trace


def test_a_thousand_simulated_seconds_do_not_wait_for_real_time() -> None:
    started = time.perf_counter()
    trace = simulate(seed=1)
    wall = time.perf_counter() - started
    assert trace[-1][0] >= SIM_SECONDS - 3.0
    assert len(trace) > 3000  # ten robots, one message per ~1.75 s each
    # Not a speed test (about 0.1 s here, more on a loaded machine): real time would
    # have taken SIM_SECONDS; virtual time takes only what the CPU needs.
    assert wall < SIM_SECONDS / 10, f"{SIM_SECONDS} simulated seconds took {wall:.2f} s"


def test_same_seed_gives_identical_traces_and_another_seed_does_not() -> None:
    first, second, other = simulate(seed=7), simulate(seed=7), simulate(seed=8)
    assert first == second
    assert first != other


def test_virtual_sleep_and_timeouts_follow_virtual_time() -> None:
    async def main() -> tuple[float, float, float]:
        clock = VirtualClock()
        clock.start()
        await clock.sleep(3600)
        after_sleep = clock.now()
        await clock.sleep_until(7200.5)
        after_until = clock.now()
        with pytest.raises(TimeoutError):
            async with clock.timeout(100):
                await asyncio.sleep(10_000)
        return after_sleep, after_until, clock.now()

    started = time.perf_counter()
    assert cas_async.run(main(), virtual=True) == (3600.0, 7200.5, 7300.5)
    assert time.perf_counter() - started < 60.0  # two hours were never waited for


def test_request_timeout_runs_on_the_robot_clock() -> None:
    class Silent(Recorder):
        async def get_intra_msg_reply(self, msg: Message) -> Message | None:
            return None

    async def main() -> float:
        clock = VirtualClock()
        stack = [Recorder(), Silent()]
        async with Robot(1, stack, clock=clock, messages=STACK_MESSAGES):
            with pytest.raises(RequestTimeout, match="within 30 s"):
                await stack[0].request_down(Query(1), timeout=30)
            return clock.now()

    assert cas_async.run(main(), virtual=True) == pytest.approx(30.0)


def test_threads_still_wake_the_virtual_loop() -> None:
    async def main() -> int:
        return await asyncio.get_running_loop().run_in_executor(None, sum, [1, 2, 3])

    assert cas_async.run(main(), virtual=True) == 6


def test_virtual_time_cannot_go_backwards() -> None:
    loop = VirtualTimeLoop()
    try:
        loop.advance(2.5)
        assert loop.time() == 2.5
        with pytest.raises(ValueError, match="cannot go backwards"):
            loop.advance(-1)
    finally:
        loop.close()


async def test_scaled_clock_divides_sleeps_by_the_time_factor() -> None:
    clock = ScaledClock(time_factor=500)
    clock.start()
    started = time.perf_counter()
    await clock.sleep(10)  # 20 ms of real time
    real = time.perf_counter() - started
    assert clock.now() >= 10
    assert 0.015 < real < 2.0  # generous: only the scaling is checked, not timer accuracy
    assert clock.time_factor == 500


@pytest.mark.parametrize("factor", [0, -1, float("inf"), float("nan")])
def test_scaled_clock_refuses_impossible_factors(factor: float) -> None:
    with pytest.raises(ConfigurationError, match="time_factor must be a positive finite number"):
        ScaledClock(factor)


def test_a_clock_refuses_a_second_event_loop() -> None:
    clock = VirtualClock()

    async def use() -> None:
        async with Robot(1, [Layer()], clock=clock, messages=STACK_MESSAGES):
            pass

    cas_async.run(use(), virtual=True)
    with pytest.raises(ConfigurationError, match="started on another event loop"):
        cas_async.run(use(), virtual=True)
