"""Waiting on the wall clock from a run whose loop may be on virtual time.

On a virtual-time loop, awaiting anything lets the loop jump to its next timer
as soon as every task waits: a wall-clock wait would not hold the run, it
would let it race on. Two tools here:

* :class:`Pacer` holds a virtual run at ``pace`` simulated seconds per wall
  second. It runs in the sampler, right after a sample (see
  :class:`~cas_async.scenario.RunListener`): while the run is ahead of the wall
  clock, it blocks the loop for a short slice, then lets the loop make one pass
  (the view's sockets, a signal's callback) without letting time move, since
  the sampler is ready to run again at the same instant. The robots only see
  the loop stand still: their results are the same with or without pacing.
* :func:`~cas_async.wall_bounded` (re-exported here) awaits something for at
  most some wall seconds, on any loop (a thread's timer ends the wait: the loop's
  own clock may be virtual);
* :class:`WallTicker` calls a function on the loop every so many wall seconds, from
  a thread (the view's server sweeps its connections so: a loop timer would be
  virtual).
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections.abc import Callable
from typing import Final, final

from .. import wall_bounded

__all__ = ["Pacer", "WallTicker", "wall_bounded"]


SLICE: Final = 0.01
"""Wall seconds the loop is blocked at a time while a paced run waits."""
LAG_LIMIT: Final = 1.0
"""Wall seconds a paced run may fall behind (a slow stretch) before the pace starts anew."""


@final
class Pacer:
    """Holds a run to ``pace`` simulated seconds per wall second (see the module docs).

    Args:
        pace: simulated seconds per wall second (positive).
        wall_clock: reads the wall clock, in seconds.
        block: blocks the thread for some wall seconds (the loop with it).
        stopping: while it returns true, nothing is held (the run is being stopped).

    Raises:
        ValueError: ``pace`` is not a positive finite number.
    """

    def __init__(
        self,
        pace: float,
        *,
        wall_clock: Callable[[], float] = time.perf_counter,
        block: Callable[[float], None] = time.sleep,
        stopping: Callable[[], bool] = lambda: False,
    ) -> None:
        if not (0 < pace < float("inf")):
            raise ValueError(
                f"pace must be a positive number of simulated s per wall s, got {pace}"
            )
        self.pace = pace
        self._wall_clock = wall_clock
        self._block = block
        self._stopping = stopping
        self._origin: tuple[float, float] | None = None  # (simulated, wall) that match
        self.held = 0.0
        """Wall seconds the run was held so far."""

    async def hold(self, t: float) -> None:
        """Returns once the wall clock has caught up with simulated instant ``t``."""
        now = self._wall_clock()
        if self._origin is None:
            self._origin = (t, now)
        sim0, wall0 = self._origin
        due = wall0 + (t - sim0) / self.pace
        if now - due > LAG_LIMIT:  # the run fell behind: go on at the pace from here
            self._origin = (t, now)
            return
        while (left := due - now) > 0 and not self._stopping():
            self._block(min(left, SLICE))
            await asyncio.sleep(0)  # one pass of the loop at this same instant
            later = self._wall_clock()
            self.held += later - now
            now = later


@final
class WallTicker:
    """Calls ``callback`` on ``loop`` every ``period`` wall seconds, until closed.

    A daemon thread waits on the wall clock and hands the call to the loop
    (``call_soon_threadsafe``), so the callback runs on the loop's thread, between
    its other callbacks, whatever the loop's own clock says.
    """

    def __init__(
        self, loop: asyncio.AbstractEventLoop, period: float, callback: Callable[[], None]
    ) -> None:
        self._loop = loop
        self._period = period
        self._callback = callback
        self._stopped = threading.Event()
        self._thread = threading.Thread(target=self._run, name="cas_async wall ticker", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stopped.wait(self._period):
            with contextlib.suppress(RuntimeError):  # the loop closed: nothing left to sweep
                self._loop.call_soon_threadsafe(self._tick)

    def _tick(self) -> None:
        if not self._stopped.is_set():
            self._callback()

    def close(self) -> None:
        """Stops calling (the thread ends within a period); idempotent."""
        self._stopped.set()
