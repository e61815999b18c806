"""Request deadlines: one timer per layer, exact expiry, bounded memory."""

from __future__ import annotations

import asyncio

import cas_async
from cas_async import Message, RequestTimeout, Robot, VirtualClock
from cas_async._core._deadlines import Deadlines
from cas_async.testing import wait_all_tasks_blocked
from tests.stacks import STACK_MESSAGES, Query, Recorder


def test_deadlines_expire_live_keys_in_order_at_their_time() -> None:
    async def main() -> list[tuple[float, int]]:
        loop = asyncio.get_running_loop()
        live = {1: None, 2: None, 3: None, 4: None}
        fired: list[tuple[float, int]] = []
        deadlines = Deadlines(loop, live, lambda key: fired.append((loop.time(), key)))
        deadlines.add(1, 30.0)
        deadlines.add(2, 10.0)  # earlier than the armed timer: re-armed
        deadlines.add(3, 20.0)
        deadlines.add(4, 20.0)
        del live[3]  # answered: must not fire
        await asyncio.sleep(100)
        return fired

    assert cas_async.run(main(), virtual=True) == [(10.0, 2), (20.0, 4), (30.0, 1)]


def test_answered_requests_do_not_accumulate() -> None:
    async def main() -> int:
        loop = asyncio.get_running_loop()
        live: dict[int, None] = {}
        deadlines = Deadlines(loop, live, lambda key: None)
        for key in range(10_000):
            live[key] = None
            deadlines.add(key, 1_000.0 + key)
            del live[key]  # answered at once, long before its deadline
        return len(deadlines._heap)

    assert cas_async.run(main(), virtual=True) < 600


def test_many_requests_with_mixed_timeouts_each_time_out_at_their_own_deadline() -> None:
    class Silent(Recorder):
        async def get_intra_msg_reply(self, msg: Message) -> Message | None:
            return None

    async def main() -> list[tuple[int, float]]:
        clock = VirtualClock()
        stack = [Recorder(), Silent()]
        outcomes: list[tuple[int, float]] = []

        async def ask(timeout: int) -> None:
            try:
                await stack[0].request_down(Query(timeout), timeout=timeout)
            except RequestTimeout:
                outcomes.append((timeout, clock.now()))

        async with Robot(1, stack, clock=clock, messages=STACK_MESSAGES):
            await asyncio.gather(*(ask(t) for t in (50, 10, 30, 20, 40)))
        return outcomes

    assert cas_async.run(main(), virtual=True) == [(t, float(t)) for t in (10, 20, 30, 40, 50)]


class Slow(Recorder):
    """Answers a query after a long simulated time."""

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        await self.clock.sleep(10_000.0)
        return await super().get_intra_msg_reply(msg)


def test_an_infinite_timeout_waits_as_long_as_it_takes_and_arms_no_timer() -> None:
    async def main() -> tuple[float, int, int]:
        clock = VirtualClock()
        asker = Recorder()
        robot = Robot(1, [asker, Slow()], clock=clock, messages=STACK_MESSAGES)
        async with robot:
            pending = asyncio.ensure_future(asker.request_down(Query(4), timeout=float("inf")))
            await wait_all_tasks_blocked()
            loop = asyncio.get_running_loop()
            assert isinstance(loop, cas_async.VirtualTimeLoop)
            armed = loop.timer_deadlines()
            answer = await pending
        return clock.now(), answer.value, armed  # type: ignore[attr-defined]

    # The only timer is the answerer's sleep: the request's infinite timeout armed none.
    assert cas_async.run(main(), virtual=True) == (10_000.0, 8, [10_000.0])
