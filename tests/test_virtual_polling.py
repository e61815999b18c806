"""The virtual-time loop polls real I/O every few passes, and still hears signals and threads."""

from __future__ import annotations

import asyncio
import selectors
import signal
import threading
from typing import Any

import pytest

from cas_async import VirtualTimeLoop
from cas_async._time._virtual_loop import POLL_EVERY


class CountingSelector(selectors.DefaultSelector):
    """The real selector, counting the polls that do not wait (``timeout == 0``)."""

    polls = 0

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        if timeout == 0:
            CountingSelector.polls += 1
        return super().select(timeout)


@pytest.fixture
def counted(monkeypatch: pytest.MonkeyPatch) -> type[CountingSelector]:
    CountingSelector.polls = 0
    monkeypatch.setattr(selectors, "DefaultSelector", CountingSelector)
    return CountingSelector


def run_virtual(main: Any) -> Any:
    with asyncio.Runner(loop_factory=VirtualTimeLoop) as runner:
        return runner.run(main())


def test_a_busy_loop_polls_real_io_once_every_few_passes(counted: type[CountingSelector]) -> None:
    passes = 100 * POLL_EVERY

    async def main() -> None:
        before = counted.polls
        for _ in range(passes):
            await asyncio.sleep(0)
        counted.polls -= before

    run_virtual(main)
    assert passes // POLL_EVERY - 2 <= counted.polls <= passes // POLL_EVERY + 2


def test_a_loop_jumping_through_time_polls_once_every_few_passes(
    counted: type[CountingSelector],
) -> None:
    jumps = 100 * POLL_EVERY

    async def main() -> float:
        before = counted.polls
        for _ in range(jumps):
            await asyncio.sleep(1.0)  # idle: each pass jumps one second
        counted.polls -= before
        return asyncio.get_running_loop().time()

    assert run_virtual(main) == jumps
    assert counted.polls <= 4 * jumps // POLL_EVERY  # two passes a jump; polled each: 2 * jumps


@pytest.mark.skipif(not hasattr(signal, "SIGUSR1"), reason="needs SIGUSR1")
def test_a_signal_reaches_a_busy_loop_within_a_few_passes() -> None:
    async def main() -> int:
        loop = asyncio.get_running_loop()
        heard = asyncio.Event()
        loop.add_signal_handler(signal.SIGUSR1, heard.set)
        try:
            # To this thread: its handler has noted the signal once the call returns.
            signal.pthread_kill(threading.get_ident(), signal.SIGUSR1)
            passes = 0
            while not heard.is_set() and passes < 100 * POLL_EVERY:
                await asyncio.sleep(0)  # busy: never idle, so never a real wait
                passes += 1
            return passes
        finally:
            loop.remove_signal_handler(signal.SIGUSR1)

    assert run_virtual(main) <= 2 * POLL_EVERY + 2


def test_work_from_another_thread_runs_on_the_next_pass_of_a_busy_loop() -> None:
    async def main() -> int:
        loop = asyncio.get_running_loop()
        done = asyncio.Event()
        handed = threading.Event()

        def hand_over() -> None:
            loop.call_soon_threadsafe(done.set)
            handed.set()

        thread = threading.Thread(target=hand_over)
        thread.start()
        thread.join(timeout=10.0)  # the work is handed over: on the ready queue already
        assert handed.is_set()
        passes = 0
        while not done.is_set() and passes < 100 * POLL_EVERY:
            await asyncio.sleep(0)
            passes += 1
        return passes

    assert run_virtual(main) <= 2
