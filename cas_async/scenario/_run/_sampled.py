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
from ..._time._virtual_loop import VirtualTimeLoop
from ..output._results import RunStatus

__all__ = ["first_ended", "sampled_until_end", "settled"]


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
    loop was busy). Returns which end (see :class:`~cas_async.scenario.RunStatus`:
    completed if the objective was met at or before any other end, stopped when the
    robots stopped first); the exception is that of a failed run (a layer's, or the
    sampling's).
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
    swarm, sampling_task = waits["swarm"], waits["sampling"]
    failure = next(
        (task.exception() for task in (swarm, sampling_task) if task in done and task.exception()),
        None,
    )
    if failure is None and swarm in done:
        # Every robot stopped. What else happens at this instant is still the run's
        # (the objective may be met by it): a tie goes to the objective.
        await settled()
    if complete.is_set():  # met at or before whatever else ended: completed
        return RunStatus.COMPLETED, None
    if failure is not None:
        return RunStatus.FAILED, failure
    if swarm in done:
        return RunStatus.STOPPED, None
    if "stop" in waits and waits["stop"] in done:
        return RunStatus.INTERRUPTED, None
    return RunStatus.TIMED_OUT, None


async def settled() -> None:
    """Returns once everything due at this instant has run (on virtual time; else at once).

    On a :class:`~cas_async.VirtualTimeLoop` the loop is then idle and time has not
    moved: what a run decides next sees every event of its instant, however the
    robots' tasks were ordered.
    """
    loop = asyncio.get_running_loop()
    if isinstance(loop, VirtualTimeLoop):
        await loop.idle()
