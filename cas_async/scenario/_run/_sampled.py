"""A run observed as it goes: sampled on its own clock until it ends, whichever way.

A run in one process without lookahead windows (scaled real time, or virtual time
with no network latency), and a world following its workers on scaled time,
sample their robots every ``run.trace_interval`` simulated seconds, at absolute
instants, until the mission is complete, ``run.max_time`` passes, a stop is
asked, or the robots (or the sampling) fail.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable, Coroutine, Iterable
from typing import Any

from ..._time._clock import Clock
from ..output._results import RunStatus

__all__ = ["first_ended", "sampled_until_end"]


async def first_ended(tasks: Iterable[asyncio.Future[Any]]) -> set[asyncio.Future[Any]]:
    """Waits until one of ``tasks`` ends, cancels the others; which had ended by then.

    Every task has finished when this returns; a task's own failure is not raised
    here: the caller reads it from the task.
    """
    tasks = list(tasks)
    try:
        done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in tasks:
            task.cancel()
        for task in tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
    return done


async def sampled_until_end(
    running: Coroutine[Any, Any, None],
    clock: Clock,
    max_time: float,
    interval: float,
    complete: asyncio.Event,
    stop: asyncio.Event | None,
    sample: Callable[[float], None],
    hold: Callable[[float], Coroutine[Any, Any, None]],
    behind: Callable[[float], None] = lambda seconds: None,
) -> tuple[RunStatus, BaseException | None]:
    """Samples every ``interval`` simulated seconds, awaiting ``hold`` after each, until an end.

    ``behind`` is told, at each sample, how many simulated seconds after its instant
    it was taken: on scaled time, how far the run fell behind the wall clock (its
    loop was busy). Returns which end; the exception is that of a failed run (a
    layer's, or the sampling's).
    """

    async def sampling() -> None:
        tick = 0
        while True:
            await clock.sleep_until(tick * interval)  # absolute instants: no drift
            sample(now := clock.now())
            behind(now - tick * interval)
            await hold(now)
            tick += 1

    waits = {
        "complete": asyncio.ensure_future(complete.wait()),
        "timeout": asyncio.ensure_future(clock.sleep_until(max_time)),
        "swarm": asyncio.ensure_future(running),
        "sampling": asyncio.ensure_future(sampling()),
    }
    if stop is not None:
        waits["stop"] = asyncio.ensure_future(stop.wait())
    done = await first_ended(waits.values())
    if waits["complete"] in done:
        return RunStatus.COMPLETED, None
    if waits["swarm"] in done or waits["sampling"] in done:
        error = (waits["swarm"] if waits["swarm"] in done else waits["sampling"]).exception()
        return RunStatus.FAILED, error or RuntimeError(
            "every robot stopped (each layer's termination condition held) "
            "before the mission was complete"
        )
    if "stop" in waits and waits["stop"] in done:
        return RunStatus.INTERRUPTED, None
    return RunStatus.TIMED_OUT, None
