"""request(..., retries=n): the same request sent again after each timeout; silent partners."""

from __future__ import annotations

import asyncio
import math
import re

import pytest

import cas_async
from cas_async import (
    Faults,
    FaultyTransport,
    MemoryTransport,
    Message,
    RequestTimeout,
    Robot,
    Swarm,
    Transport,
    VirtualClock,
)
from tests.stacks import STACK_MESSAGES, Answer, Note, Query, Recorder


def robot(robot_id: int, layer: Recorder, transport: Transport, clock: VirtualClock) -> Robot:
    return Robot(robot_id, [layer], transport=transport, clock=clock, messages=STACK_MESSAGES)


class Mute(Recorder):
    """Records what it is asked and never answers."""

    async def handle_msg(self, msg: Message) -> None:
        self.external.append(msg)


class Slow(Recorder):
    """Answers each query after ``delay`` simulated seconds."""

    def __init__(self, delay: float) -> None:
        super().__init__()
        self.delay = delay

    async def handle_msg(self, msg: Message) -> None:
        self.external.append(msg)
        await self.clock.sleep(self.delay)
        assert isinstance(msg, Query)
        self.reply(msg, Answer(msg.value * 2, 0))


def test_a_lost_request_is_sent_again_and_answered_after_one_timeout() -> None:
    async def main() -> tuple[float, int, int, dict[str, int], dict[str, int]]:
        clock, memory = VirtualClock(), MemoryTransport()
        lossy = FaultyTransport(memory, Faults(loss=1.0), clock=clock)
        asker, answerer = Recorder(), Recorder()
        robots = [robot(1, asker, lossy, clock), robot(2, answerer, memory, clock)]
        async with Swarm(robots):
            asking = asyncio.ensure_future(asker.request(2, Query(21), timeout=3.0, retries=2))
            await asyncio.sleep(0)  # the first attempt is on the (lossy) wire
            assert lossy.stats["sent"] == 1
            lossy.faults = Faults()  # the next attempt gets through
            reply = await asking
            at = clock.now()
        return at, reply.value, len(answerer.external), lossy.stats, robots[0].dropped  # type: ignore[attr-defined]

    at, value, handled, stats, dropped = cas_async.run(main(), virtual=True)
    assert (at, value, handled) == (3.0, 42, 1)
    assert (stats["sent"], stats["lost"]) == (2, 1)
    assert dropped == {}


@pytest.mark.parametrize("retries", [1, 3])
def test_when_every_attempt_is_lost_the_request_gives_up_after_all_of_them(retries: int) -> None:
    async def main() -> tuple[RequestTimeout, float, dict[str, int], int]:
        clock, memory = VirtualClock(), MemoryTransport()
        lossy = FaultyTransport(memory, Faults(loss=1.0), clock=clock)
        asker, answerer = Recorder(), Recorder()
        async with Swarm([robot(1, asker, lossy, clock), robot(2, answerer, memory, clock)]):
            with pytest.raises(RequestTimeout) as caught:
                await asker.request(2, Query(1), timeout=2.5, retries=retries)
            return caught.value, clock.now(), lossy.stats, len(answerer.external)

    error, at, stats, handled = cas_async.run(main(), virtual=True)
    attempts = retries + 1
    assert at == attempts * 2.5
    assert (error.peer, error.attempts) == (2, attempts)
    assert re.fullmatch(
        rf"robot 1 Recorder\(L0\): no reply from robot 2 to Query #\d+ within 2.5 s "
        rf"\({attempts} attempts\)",
        str(error),
    )
    assert (stats["sent"], stats["lost"]) == (attempts, attempts)
    assert handled == 0


def test_a_silent_partner_is_asked_the_same_request_each_time_and_handles_it_once() -> None:
    async def main() -> tuple[RequestTimeout, int, dict[str, int], float | None]:
        clock, memory = VirtualClock(), MemoryTransport()
        asker, mute = Recorder(), Mute()
        robots = [robot(1, asker, memory, clock), robot(2, mute, memory, clock)]
        async with Swarm(robots):
            with pytest.raises(RequestTimeout) as caught:
                await asker.request(2, Query(1), timeout=2.0, retries=3)
            return caught.value, len(mute.external), robots[1].dropped, robots[1].last_heard(1)

    error, handled, dropped, heard = cas_async.run(main(), virtual=True)
    assert error.attempts == 4
    assert handled == 1  # same msg_id every time: the repetitions are duplicates
    assert dropped == {"duplicate": 3}
    assert heard == 6.0  # the last attempt went out at 3 * 2.0


def test_without_retries_a_request_times_out_once_as_before() -> None:
    async def main() -> tuple[RequestTimeout, float, int]:
        clock, memory = VirtualClock(), MemoryTransport()
        asker, mute = Recorder(), Mute()
        async with Swarm([robot(1, asker, memory, clock), robot(2, mute, memory, clock)]):
            with pytest.raises(RequestTimeout) as caught:
                await asker.request(2, Query(1), timeout=2.0)
            await clock.sleep(10.0)
            return caught.value, clock.now() - 10.0, len(mute.external)

    error, at, handled = cas_async.run(main(), virtual=True)
    assert at == 2.0
    assert (error.peer, error.attempts, handled) == (2, 1, 1)
    assert re.fullmatch(
        r"robot 1 Recorder\(L0\): no reply from robot 2 to Query #\d+ within 2 s", str(error)
    )
    assert isinstance(error, TimeoutError)


def test_without_retries_an_answer_comes_as_before() -> None:
    async def main() -> tuple[float, int]:
        clock, memory = VirtualClock(), MemoryTransport()
        asker, answerer = Recorder(), Slow(1.5)
        async with Swarm([robot(1, asker, memory, clock), robot(2, answerer, memory, clock)]):
            reply = await asker.request(2, Query(4), timeout=2.0, retries=0)
            return clock.now(), reply.value  # type: ignore[attr-defined]

    assert cas_async.run(main(), virtual=True) == (1.5, 8)


@pytest.mark.parametrize("retries", [-1, -10])
def test_negative_retries_are_refused_before_anything_is_sent(retries: int) -> None:
    async def main() -> tuple[int, int]:
        clock, memory = VirtualClock(), MemoryTransport()
        asker, answerer = Recorder(), Recorder()
        async with Swarm([robot(1, asker, memory, clock), robot(2, answerer, memory, clock)]):
            with pytest.raises(ValueError, match=f"retries must be >= 0, got {retries}"):
                await asker.request(2, Query(1), timeout=1.0, retries=retries)
            await clock.sleep(1.0)
            return len(answerer.external), asker.counters.sent_external

    assert cas_async.run(main(), virtual=True) == (0, 0)


def test_a_late_reply_to_an_earlier_attempt_answers_the_current_one() -> None:
    async def main() -> tuple[float, int, int, dict[str, int], dict[str, int], int]:
        clock, memory = VirtualClock(), MemoryTransport()
        asker, slow = Recorder(), Slow(3.0)  # answers after the first attempt timed out
        robots = [robot(1, asker, memory, clock), robot(2, slow, memory, clock)]
        async with Swarm(robots):
            reply = await asker.request(2, Query(5), timeout=2.0, retries=2)
            at = clock.now()
            await clock.sleep(10.0)
        return (
            at,
            reply.value,  # type: ignore[attr-defined]
            len(slow.external),
            robots[0].dropped,
            robots[1].dropped,
            robots[1].counters()["replies_resent"],
        )

    at, value, handled, asker_dropped, answerer_dropped, resent = cas_async.run(
        main(), virtual=True
    )
    assert (at, value, handled) == (3.0, 10, 1)
    assert asker_dropped == {}  # accepted, not a "late_reply"
    # The retry at t=2 came while the first was being handled: nothing kept to re-send yet.
    assert (answerer_dropped, resent) == ({"duplicate": 1}, 0)


def test_a_reply_after_the_last_attempt_gave_up_is_dropped_as_late() -> None:
    async def main() -> tuple[float, dict[str, int], int]:
        clock, memory = VirtualClock(), MemoryTransport()
        asker, slow = Recorder(), Slow(10.0)
        robots = [robot(1, asker, memory, clock), robot(2, slow, memory, clock)]
        async with Swarm(robots):
            with pytest.raises(RequestTimeout):
                await asker.request(2, Query(5), timeout=2.0, retries=1)
            gave_up = clock.now()
            await clock.sleep(20.0)
        return gave_up, robots[0].dropped, asker.counters.received_external

    gave_up, dropped, received = cas_async.run(main(), virtual=True)
    assert gave_up == 4.0
    assert dropped == {"late_reply": 1}
    assert received == 0


def test_concurrent_requests_with_retries_over_a_bad_wire_each_get_their_own_reply() -> None:
    async def main() -> tuple[list[int], list[int]]:
        clock, memory = VirtualClock(), MemoryTransport()
        faults = Faults(loss=0.3, duplicate=0.2, delay=(0.0, 0.5))
        asker_net = FaultyTransport(memory, faults, seed=3, clock=clock)
        answer_net = FaultyTransport(memory, faults, seed=4, clock=clock)
        asker, answerer = Recorder(), Recorder()
        robots = [robot(1, asker, asker_net, clock), robot(2, answerer, answer_net, clock)]
        async with Swarm(robots):
            # Fewer at once than the answerer keeps replies for one asker.
            replies = await asyncio.gather(
                *(asker.request(2, Query(k), timeout=1.0, retries=20) for k in range(8))
            )
        handled = sorted(m.value for m in answerer.external)  # type: ignore[attr-defined]
        return [reply.value for reply in replies], handled  # type: ignore[attr-defined]

    values, handled = cas_async.run(main(), virtual=True)
    assert values == [2 * k for k in range(8)]
    assert handled == list(range(8))  # each once, however often it was sent


@pytest.mark.parametrize("retries", [0, 2])
def test_one_message_object_may_serve_two_requests_at_once(retries: int) -> None:
    async def main() -> list[object]:
        clock, memory = VirtualClock(), MemoryTransport()
        asker, answerer = Recorder(), Slow(1.0)
        async with Swarm([robot(1, asker, memory, clock), robot(2, answerer, memory, clock)]):
            query = Query(3)
            first = asyncio.ensure_future(asker.request(2, query, timeout=5.0, retries=retries))
            await clock.sleep(0.5)
            second = asyncio.ensure_future(asker.request(2, query, timeout=5.0, retries=retries))
            done = await asyncio.wait_for(  # virtual seconds: a hang fails here
                asyncio.gather(first, second, return_exceptions=True), 1_000.0
            )
        return [getattr(r, "value", r) for r in done]

    try:
        values = cas_async.run(main(), virtual=True)
    except TimeoutError:
        pytest.fail("a request outlived its timeout by far: it waits for a forgotten reply")
    assert values == [6, 6]


# -- silent partners -------------------------------------------------------------------


def test_silent_for_and_last_heard_are_in_simulated_seconds() -> None:
    async def main() -> list[tuple[float | None, float]]:
        await asyncio.sleep(100.0)  # the loop's clock is not the simulated clock
        clock, memory = VirtualClock(), MemoryTransport()
        listener, talker = Recorder(), Recorder()
        robots = [robot(1, listener, memory, clock), robot(2, talker, memory, clock)]
        seen: list[tuple[float | None, float]] = []
        async with Swarm(robots):
            seen.append((robots[0].last_heard(2), listener.silent_for(2)))
            await clock.sleep(3.0)
            talker.send(1, Note("hello", []))
            await clock.sleep(7.5)
            seen.append((robots[0].last_heard(2), listener.silent_for(2)))
            talker.send(1, Note("again", []))
            await clock.sleep(0.5)
            seen.append((robots[0].last_heard(2), listener.silent_for(2)))
            seen.append((robots[0].last_heard(3), listener.silent_for(3)))  # never heard
        return seen

    assert cas_async.run(main(), virtual=True) == [
        (None, math.inf),
        (3.0, 7.5),
        (10.5, 0.5),
        (None, math.inf),
    ]


def test_a_reply_counts_as_hearing_from_the_partner() -> None:
    async def main() -> tuple[float | None, float]:
        clock, memory = VirtualClock(), MemoryTransport()
        asker, answerer = Recorder(), Slow(4.0)
        robots = [robot(1, asker, memory, clock), robot(2, answerer, memory, clock)]
        async with Swarm(robots):
            await asker.request(2, Query(1), timeout=10.0)
            await clock.sleep(1.0)
            return robots[0].last_heard(2), asker.silent_for(2)

    assert cas_async.run(main(), virtual=True) == (4.0, 1.0)
