"""Virtual time in lookahead windows: a window closes once every event before its end has run."""

from __future__ import annotations

import asyncio
import math
import threading

import pytest

from cas_async import VirtualTimeLoop
from cas_async._time._deliveries import DATAGRAM, Deliveries
from cas_async.scenario._processes._windows import Held, Steps, Windows

L = 0.5


def virtual_loop() -> VirtualTimeLoop:
    loop = asyncio.get_running_loop()
    assert isinstance(loop, VirtualTimeLoop)
    return loop


class Log:
    """What happened, in order: events at their instants, and the windows closed."""

    def __init__(self, loop: VirtualTimeLoop) -> None:
        self.loop = loop
        self.entries: list[tuple[str, float, float]] = []
        self.over = loop.create_future()

    def event(self, label: str) -> None:
        self.entries.append((label, self.loop.time(), math.nan))

    def at(self, when: float, label: str = "event") -> None:
        self.loop.call_at(when, self.event, label)

    async def close(self, end: float, next_event: float) -> float | None:
        """Closes at ``end``: the next window is ``L`` from the next event; None when no event."""
        self.entries.append(("close", end, next_event))
        if math.isinf(next_event):
            self.over.set_result(None)
            return None
        return next_event + L

    def closes(self) -> list[tuple[float, float]]:
        return [(end, following) for label, end, following in self.entries if label == "close"]


@pytest.mark.cas_virtual
async def test_every_event_before_a_windows_end_runs_before_it_closes() -> None:
    loop = virtual_loop()
    log = Log(loop)
    for when in (0.1, 0.3, 0.45, 0.6, 1.7):
        log.at(when)
    loop.call_at(0.2, log.at, 0.4, "made in the window")  # an event an event made
    windows = Windows(loop, L, log.close)
    loop.run_windows(windows)
    try:
        await log.over
    finally:
        loop.run_windows(None)
    assert [(label, at) for label, at, _ in log.entries] == [
        ("event", 0.1),
        ("event", 0.3),
        ("made in the window", 0.4),
        ("event", 0.45),
        ("close", 0.5),
        ("event", 0.6),
        ("close", 1.1),  # the next event (0.6) plus L
        ("event", 1.7),
        ("close", 2.2),
    ]
    assert log.closes() == [(0.5, 0.6), (1.1, 1.7), (2.2, math.inf)]
    assert (windows.rounds, windows.over, windows.end, windows.failure) == (3, True, math.inf, None)


@pytest.mark.cas_virtual
async def test_an_event_at_a_windows_end_belongs_to_the_next_window() -> None:
    loop = virtual_loop()
    log = Log(loop)
    log.at(L, "at the end")
    Deliveries.of().at(2 * L, (DATAGRAM, 1, 1), lambda: log.event("delivery at the next end"))
    loop.run_windows(Windows(loop, L, log.close))
    try:
        await log.over
    finally:
        loop.run_windows(None)
    assert [(label, at) for label, at, _ in log.entries] == [
        ("close", L),
        ("at the end", L),
        ("close", 2 * L),
        ("delivery at the next end", 2 * L),  # a delivery is an event too
        ("close", 3 * L),
    ]


@pytest.mark.cas_virtual
async def test_the_closers_end_starts_the_next_window_wherever_it_is() -> None:
    loop = virtual_loop()
    log = Log(loop)
    for when in (0.2, 0.9, 1.3, 1.6):
        log.at(when)
    ends = iter([1.0, 1.5, None])

    async def close(end: float, next_event: float) -> float | None:
        log.entries.append(("close", end, next_event))
        following = next(ends)
        if following is None:
            log.over.set_result(None)
        return following

    windows = Windows(loop, 0.5, close)
    loop.run_windows(windows)
    try:
        await log.over
        assert windows.over
        # None ended the windows: time moves freely again, with no more closing.
        await asyncio.sleep(5.0)
    finally:
        loop.run_windows(None)
    assert log.closes() == [(0.5, 0.9), (1.0, 1.3), (1.5, 1.6)]
    assert [at for label, at, _ in log.entries if label == "event"] == [0.2, 0.9, 1.3, 1.6]


@pytest.mark.cas_virtual
async def test_once_the_windows_end_an_idle_loop_waits_for_threads_without_closing_again() -> None:
    loop = virtual_loop()
    log = Log(loop)
    windows = Windows(loop, L, log.close)
    loop.run_windows(windows)
    try:
        await log.over  # nothing was scheduled: the first window was the last
        woken = loop.create_future()
        # Nothing is scheduled: only another thread wakes the loop now.
        thread = threading.Timer(0.1, loop.call_soon_threadsafe, (woken.set_result, "woken"))
        thread.start()
        assert await woken == "woken"  # (no timeout: a timer would be scheduled)
        thread.join()
    finally:
        loop.run_windows(None)
    assert log.closes() == [(L, math.inf)]
    assert windows.rounds == 1


@pytest.mark.cas_virtual
async def test_a_closer_that_raises_ends_the_windows_and_says_so() -> None:
    loop = virtual_loop()
    log = Log(loop)
    log.at(0.2)
    log.at(0.7)
    failed = loop.create_future()

    async def close(end: float, next_event: float) -> float | None:
        raise RuntimeError(f"cannot close at {end}")

    windows = Windows(loop, L, close, failed=lambda: failed.set_result(loop.time()))
    loop.run_windows(windows)
    try:
        assert await failed == 0.2  # closing at 0.5, before the next event
    finally:
        loop.run_windows(None)
    assert isinstance(windows.failure, RuntimeError)
    assert str(windows.failure) == "cannot close at 0.5"
    assert (windows.over, windows.end, windows.rounds) == (True, math.inf, 0)


@pytest.mark.cas_virtual
async def test_quick_closes_a_window_at_once_and_counts_a_round() -> None:
    loop = virtual_loop()
    log = Log(loop)
    for when in (0.1, 0.7, 1.5, 2.6):
        log.at(when)
    quick_calls: list[tuple[float, float]] = []

    def quick(end: float, next_event: float) -> float | None:
        quick_calls.append((end, next_event))
        return None if next_event > 2.0 else next_event + L  # the last ones need close

    windows = Windows(loop, L, log.close, quick=quick)
    loop.run_windows(windows)
    try:
        await log.over
    finally:
        loop.run_windows(None)
    assert quick_calls == [(0.5, 0.7), (1.2, 1.5), (2.0, 2.6), (3.1, math.inf)]
    assert log.closes() == [(2.0, 2.6), (3.1, math.inf)]
    assert windows.rounds == 4
    assert [at for label, at, _ in log.entries if label == "event"] == [0.1, 0.7, 1.5, 2.6]


@pytest.mark.cas_virtual
async def test_while_a_window_closes_time_stands_and_the_loop_waits_for_threads() -> None:
    loop = virtual_loop()
    log = Log(loop)
    log.at(0.8, "after the window")
    idle_seen, news = threading.Event(), loop.create_future()
    idle_times: list[float] = []

    def idle() -> None:
        idle_times.append(loop.time())
        idle_seen.set()

    async def close(end: float, next_event: float) -> float | None:
        if end == L:  # the first window waits for the others' news
            assert await news == "the others' window"
        return await log.close(end, next_event)

    def other_process() -> None:  # answers once the loop waited for it in vain
        if idle_seen.wait(30.0):
            loop.call_soon_threadsafe(news.set_result, "the others' window")

    thread = threading.Thread(target=other_process)
    thread.start()
    windows = Windows(loop, L, close, idle=idle)
    loop.run_windows(windows)
    try:
        await log.over
    finally:
        loop.run_windows(None)
        thread.join()
    assert set(idle_times) == {0.0}  # waited at least once, and time did not move meanwhile
    assert [(label, at) for label, at, _ in log.entries] == [
        ("close", L),
        ("after the window", 0.8),
        ("close", 1.3),
    ]


@pytest.mark.cas_virtual
async def test_held_windows_never_move_time_and_call_idle_while_waiting() -> None:
    loop = virtual_loop()
    ran, idle_calls, news = [], threading.Event(), loop.create_future()
    loop.call_at(1.0, ran.append, "timer at 1")

    def other_process() -> None:
        if idle_calls.wait(30.0):
            loop.call_soon_threadsafe(news.set_result, "news")

    thread = threading.Thread(target=other_process)
    thread.start()
    loop.run_windows(Held(idle=idle_calls.set))
    try:
        assert await news == "news"  # threads still wake it
        assert (loop.time(), ran) == (0.0, [])
    finally:
        loop.run_windows(None)
        thread.join()
    await asyncio.sleep(2.0)
    assert ran == ["timer at 1"]  # freed, time moves on
    assert Held().end == -math.inf


def test_steps_count_where_windows_end_and_where_a_decided_run_ends() -> None:
    steps = Steps(credit=0.1, latency=0.005, max_time=1.0, epoch=3)
    assert steps.first_end == 0.005
    assert steps.next_end(0.097) == 0.1  # a window never crosses a step
    assert not steps.ended(0.05)
    assert steps.ended(0.1)
    assert steps.index == 1
    assert steps.next_epoch(0.1) == pytest.approx(0.3)  # epochs turn every third step
    for end in (0.2, 0.30000000000000004):  # 3 * 0.1, as the windows count it
        assert steps.ended(end)
    assert steps.epoch_at(steps.index * steps.credit) == 1  # epoch 1 starts at step 3
    assert steps.epoch_at(0.2) is None
    assert steps.next_epoch(steps.index * steps.credit) == steps.index * steps.credit
    assert steps.next_epoch(0.31) == pytest.approx(0.6)
    # Steps start at c * credit, as counted: 3 * 0.1 is in step 3 though 3 * 0.1 / 0.1
    # rounds below 3, and 0.7 is in step 6, as 7 * 0.1 is a little above 0.7.
    assert [steps.step_of(t) for t in (0.0, 0.0999, 3 * 0.1, 0.7, 7 * 0.1)] == [0, 0, 3, 6, 7]
    assert steps.end_of_run(0.25) == pytest.approx(0.4)  # decided in step 2: ends with step 3
    assert Steps(1.0, 0.1, 10.0).next_epoch(5.0) == math.inf  # no range, no epochs
