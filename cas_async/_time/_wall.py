"""Waiting on the wall clock, from a loop whose own clock may be virtual.

On a :class:`~cas_async._time._virtual_loop.VirtualTimeLoop`, ``asyncio.timeout`` counts
loop time, which jumps when every task waits: it cannot bound a wait for another
process or a browser. :func:`wall_bounded` bounds it with a thread's timer, which
cancels the wait after that many seconds of real time, on any loop.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Awaitable
from typing import TypeVar

__all__ = ["wall_bounded"]

T = TypeVar("T")


async def wall_bounded(aw: Awaitable[T], seconds: float) -> T | None:
    """Awaits ``aw`` for at most ``seconds`` of wall time; ``None`` when the time ran out."""
    task = asyncio.ensure_future(aw)
    loop = asyncio.get_running_loop()
    expired = threading.Event()

    def expire() -> None:
        expired.set()
        with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
            loop.call_soon_threadsafe(task.cancel)

    timer = threading.Timer(seconds, expire)
    timer.daemon = True
    timer.start()
    try:
        return await task
    except asyncio.CancelledError:
        if expired.is_set():
            return None
        raise
    finally:
        timer.cancel()
