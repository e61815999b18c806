"""Waiting for a swarm in tests: until every task is blocked, or until a condition holds."""

from __future__ import annotations

import asyncio
import weakref
from collections.abc import Callable
from typing import Final

from .. import Clock, VirtualTimeLoop

__all__ = ["RunUntilTimeout", "run_until", "wait_all_tasks_blocked"]


_MAX_PASSES: Final = 100_000
"""Loop passes :func:`wait_all_tasks_blocked` waits before it calls the loop busy."""


async def wait_all_tasks_blocked() -> None:
    """Returns once every other task of the loop is blocked: waiting, with nothing to do now.

    Messages between robots of a :class:`~cas_async.MemoryTransport`, hooks, layer
    tasks and timers already due all run first; simulated time does not move. Use it
    where a test must let everything settle before it looks (``trio.testing`` has
    the same). Exact on the stdlib and virtual-time loops; on another loop (uvloop)
    it raises :class:`TypeError`.

    Raises:
        TypeError: the running loop does not show its ready callbacks.
        RuntimeError: the loop stayed busy for 100,000 passes: a task never blocks.
    """
    loop = asyncio.get_running_loop()
    if isinstance(loop, VirtualTimeLoop):  # it knows when it is idle
        await loop.idle()
        return
    # In real time one task per loop watches (two would each see the other busy);
    # every caller waits for its verdict.
    probe = _probes.get(loop)
    if probe is None or probe.done():
        probe = _probes[loop] = loop.create_task(_probe(loop))
    await asyncio.shield(probe)


_probes: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, asyncio.Task[None]] = (
    weakref.WeakKeyDictionary()
)


async def _probe(loop: asyncio.AbstractEventLoop) -> None:
    # The stdlib loop's queue of ready callbacks and heap of timers (no public API
    # shows them), read only, after each pass.
    ready = getattr(loop, "_ready", None)
    scheduled = getattr(loop, "_scheduled", None)
    if ready is None or scheduled is None:
        raise TypeError(
            f"wait_all_tasks_blocked needs the stdlib or virtual-time loop, not {type(loop)!r}"
        )
    for _ in range(_MAX_PASSES):
        await asyncio.sleep(0)
        if not ready and not (scheduled and scheduled[0].when() <= loop.time()):
            return
    raise RuntimeError(f"the loop is still busy after {_MAX_PASSES} passes: a task never waits")


class RunUntilTimeout(AssertionError):
    """:func:`run_until`'s condition stayed false for its whole timeout."""


async def run_until(
    condition: Callable[[], object],
    *,
    timeout: float,
    clock: Clock | None = None,
    step: float = 0.01,
    what: str | None = None,
) -> None:
    """Lets the robots run until ``condition()`` is true, for ``timeout`` seconds at most.

    The condition is checked whenever every task is blocked: on the virtual-time
    loop at every instant something happens (time jumps from one timer to the
    next), on other loops also every ``step`` seconds. Seconds are the clock's
    (simulated) when ``clock`` is given, else the loop's (simulated on the
    virtual-time loop).

    Raises:
        RunUntilTimeout: still false after ``timeout`` seconds, naming ``what`` (or
            the condition).
    """
    loop = asyncio.get_running_loop()
    now: Callable[[], float] = clock.now if clock is not None else loop.time
    deadline = now() + timeout
    while True:
        await wait_all_tasks_blocked()
        if condition():
            return
        left = deadline - now()
        if left <= 0:
            raise RunUntilTimeout(f"{what or _name_of(condition)} still false after {timeout:g} s")
        if isinstance(loop, VirtualTimeLoop) and clock is None:
            # Nothing changes before the next timer goes off: wake up right after it.
            later = [t - loop.time() for t in loop.timer_deadlines() if t > loop.time()]
            await asyncio.sleep(min([*later, left]))
        elif clock is not None:
            await clock.sleep(min(step, left))
        else:
            await asyncio.sleep(min(step, left))


def _name_of(condition: Callable[[], object]) -> str:
    name = getattr(condition, "__qualname__", None) or repr(condition)
    return "the condition" if name == "<lambda>" else name
