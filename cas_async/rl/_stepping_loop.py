"""A virtual-time loop that pauses where a step ends: :class:`SteppingLoop`.

The env runs an episode's swarm on this loop and advances it one step at a time:
``loop.run_until(t)`` runs every task, timer and message of the swarm whose instant
is at or before ``t``, and returns once nothing is left before ``t``'s end. Between
two calls the loop is paused, every task suspended where it waited, so the caller's
code (a training loop) stays synchronous.

The pause costs the swarm nothing it could notice: the loop stops where its idle
selector would have jumped to the next timer, without scheduling anything and
without moving its clock. The next call makes the very jump the loop would have
made, with the same arithmetic, so an episode stepped in pieces runs exactly as
the same run in one piece (same timers, same order, same instants to the last
bit). The clock stays at the last instant something happened: the step's end is
the caller's to know.

:func:`off_running_loop` runs such a call where it can run: in the caller's thread,
or, when an event loop already runs there (a notebook's), in a thread of its own
while the caller waits (asyncio runs one loop per thread at a time).
"""

from __future__ import annotations

import asyncio
import math
import selectors
import threading
from collections.abc import Callable
from typing import Any, TypeVar, final

from .. import VirtualTimeLoop

__all__ = ["SteppingLoop", "off_running_loop"]

T = TypeVar("T")


@final
class SteppingLoop(VirtualTimeLoop):
    """A :class:`~cas_async.VirtualTimeLoop` that :meth:`run_until` pauses at an instant."""

    def __init__(self) -> None:
        super().__init__()
        self._horizon = math.inf
        self._closed_at = math.nan  # the horizon a window was last closed at

    def run_until(self, horizon: float, until_done: asyncio.Future[Any] | None = None) -> None:
        """Runs everything due at or before ``horizon``, then pauses (or earlier: see below).

        Returns once the loop is idle and its next timer lies after ``horizon`` (or
        there is none), or, when ``until_done`` is given, as soon as it is done.

        Raises:
            ValueError: ``horizon`` is NaN.
        """
        if math.isnan(horizon):
            raise ValueError("run_until: the horizon must be a number, got nan")
        if until_done is not None:
            if until_done.done():
                return
            until_done.add_done_callback(_stop_loop)
        self._horizon = horizon
        try:
            self.run_forever()
        finally:
            self._horizon = math.inf
            if until_done is not None:
                until_done.remove_done_callback(_stop_loop)

    def when_idle(
        self, timeout: float | None, selector: selectors.BaseSelector
    ) -> list[tuple[selectors.SelectorKey, int]]:
        """Pauses when the next timer is after the horizon; else jumps to it as always.

        A lookahead window (a run with a latency) that ends within the step closes
        first: what comes next is at the latest the next step's actions, at the
        horizon, and closing a window never moves time.
        """
        # The next timer or delivery is what the idle jump would go to.
        horizon = self._horizon
        if horizon != math.inf and self.next_deadline() > horizon:
            windows = self._windows
            if windows is not None and self._closed_at != horizon:
                # The window closes at the pause at the latest, so that the step sees
                # what its robots did (where windows end changes no result).
                windows.clip(horizon)
                if windows.end <= horizon:
                    if windows.end == horizon:
                        self._closed_at = horizon
                    return windows.closed(horizon, selector)
            self.stop()  # this pass ends with nothing to run: run_forever returns
            return []
        return super().when_idle(timeout, selector)


def _stop_loop(future: asyncio.Future[Any]) -> None:
    future.get_loop().stop()


def off_running_loop(call: Callable[[], T]) -> T:
    """``call()``, in this thread, or in another one while an event loop runs in this one.

    A synchronous caller inside a running loop (a Jupyter cell, an ``async def``
    that calls the env) cannot run a second loop in its thread; the call then runs
    in a short-lived thread, and this one waits for it (its own loop is blocked
    meanwhile, as it would be by any synchronous call).
    """
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return call()
    outcome: list[T] = []
    failure: list[BaseException] = []

    def run() -> None:
        try:
            outcome.append(call())
        except BaseException as error:  # handed to the caller's thread, raised there
            failure.append(error)

    worker = threading.Thread(target=run, name="cas_async.rl episode")
    worker.start()
    worker.join()
    if failure:
        raise failure[0]
    return outcome[0]
