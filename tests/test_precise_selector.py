"""The stdlib loop's selector waits out a timeout to the microsecond (precise_selector.py).

Real sockets (a socketpair) and the real system calls; ``select.select`` is only
wrapped to record what it was asked to wait. How late timers go off is measured
by ``python -m benchmarks.timers``, not here: these machines are shared.
"""

from __future__ import annotations

import asyncio
import selectors
import socket
import sys
import time
from collections.abc import Iterator
from typing import Any

import pytest

from cas_async import ScaledClock, loop_factory
from cas_async._time import _precise_selector as precise
from cas_async._time._precise_selector import PreciseEpollSelector

pytestmark = pytest.mark.skipif(
    not precise.precise_selector_available(), reason="epoll only (Linux)"
)


class Recorder:
    """Passes every call on to the real ``select.select``, keeping its timeout."""

    def __init__(self, real: Any, fail: bool = False) -> None:
        self.real = real
        self.fail = fail
        self.timeouts: list[float] = []

    def __call__(self, r: Any, w: Any, x: Any, timeout: float) -> Any:
        self.timeouts.append(timeout)
        if self.fail:
            raise ValueError("filedescriptor out of range in select()")
        return self.real(r, w, x, timeout)


@pytest.fixture
def recorder(monkeypatch: pytest.MonkeyPatch) -> Recorder:
    rec = Recorder(precise.select.select)
    monkeypatch.setattr(precise.select, "select", rec)
    return rec


@pytest.fixture
def pair() -> Iterator[tuple[socket.socket, socket.socket]]:
    a, b = socket.socketpair()
    try:
        yield a, b
    finally:
        a.close()
        b.close()


@pytest.fixture
def selector(pair: tuple[socket.socket, socket.socket]) -> Iterator[PreciseEpollSelector]:
    sel = PreciseEpollSelector()
    sel.register(pair[0], selectors.EVENT_READ)
    try:
        yield sel
    finally:
        sel.close()


def test_a_sub_millisecond_timeout_is_waited_in_select_not_rounded_to_a_millisecond(
    selector: PreciseEpollSelector, recorder: Recorder
) -> None:
    started = time.monotonic()
    assert selector.select(0.0003) == []
    assert time.monotonic() - started >= 0.0003  # never shorter than asked
    assert len(recorder.timeouts) == 1
    assert 0 < recorder.timeouts[0] <= 0.0003


def test_whole_milliseconds_go_to_epoll_and_only_the_rest_to_select(
    selector: PreciseEpollSelector, recorder: Recorder
) -> None:
    started = time.monotonic()
    assert selector.select(0.0024) == []
    assert time.monotonic() - started >= 0.0024
    # epoll waited 2 ms (or a little more): select() got at most the 0.4 ms left.
    assert len(recorder.timeouts) <= 1
    assert all(0 < t <= 0.0004 + 1e-9 for t in recorder.timeouts)


def test_a_ready_descriptor_returns_from_the_epoll_wait_without_select(
    selector: PreciseEpollSelector, recorder: Recorder, pair: tuple[socket.socket, socket.socket]
) -> None:
    pair[1].send(b"x")
    ready = selector.select(5.0)
    assert [(key.fileobj, events) for key, events in ready] == [(pair[0], selectors.EVENT_READ)]
    assert recorder.timeouts == []


def test_a_descriptor_ready_during_the_fine_wait_is_returned(
    selector: PreciseEpollSelector, recorder: Recorder, pair: tuple[socket.socket, socket.socket]
) -> None:
    pair[1].send(b"x")
    ready = selector.select(0.0005)
    assert [key.fileobj for key, _ in ready] == [pair[0]]
    assert len(recorder.timeouts) == 1


def test_no_timeout_and_zero_timeout_are_the_stdlib_waits(
    selector: PreciseEpollSelector, recorder: Recorder, pair: tuple[socket.socket, socket.socket]
) -> None:
    assert selector.select(0) == []
    assert selector.select(-1.0) == []
    pair[1].send(b"x")
    assert [key.fileobj for key, _ in selector.select(None)] == [pair[0]]
    assert recorder.timeouts == []


def test_a_descriptor_out_of_selects_range_falls_back_to_milliseconds_for_good(
    monkeypatch: pytest.MonkeyPatch,
    selector: PreciseEpollSelector,
    pair: tuple[socket.socket, socket.socket],
) -> None:
    failing = Recorder(precise.select.select, fail=True)
    monkeypatch.setattr(precise.select, "select", failing)
    started = time.monotonic()
    assert selector.select(0.0003) == []
    assert time.monotonic() - started >= 0.0003
    pair[1].send(b"x")
    assert [key.fileobj for key, _ in selector.select(0.0003)] == [pair[0]]
    assert len(failing.timeouts) == 1  # tried once, then no more


@pytest.mark.skipif(sys.platform != "linux", reason="epoll only (Linux)")
def test_loop_factory_gives_the_stdlib_loop_the_precise_selector() -> None:
    loop = loop_factory(use_uvloop=False)()
    try:
        assert isinstance(loop, asyncio.SelectorEventLoop)
        assert isinstance(loop._selector, PreciseEpollSelector)  # type: ignore[attr-defined]
    finally:
        loop.close()


def test_a_scaled_clock_on_the_precise_loop_wakes_at_or_after_each_deadline(
    recorder: Recorder,
) -> None:
    async def main() -> list[float]:
        clock = ScaledClock(100.0)
        clock.start()
        lateness = []
        for n in range(1, 21):
            await clock.sleep_until(n * 0.013)  # 0.13 ms real apart: under a millisecond
            lateness.append(clock.now() - n * 0.013)
        return lateness

    with asyncio.Runner(loop_factory=loop_factory(use_uvloop=False)) as runner:
        lateness = runner.run(main())
    assert min(lateness) >= 0
    assert recorder.timeouts  # the sub-millisecond waits went through select()
