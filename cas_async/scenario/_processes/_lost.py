"""What runs across processes share: the error of a lost worker, and bounded waits for one."""

from __future__ import annotations

from collections.abc import Awaitable
from typing import TypeVar

from ..._errors import CasError
from ..._time._wall import wall_bounded

__all__ = ["WorkerLost", "WorkerRefused", "within"]

T = TypeVar("T")

_TIMED_OUT = object()


class WorkerLost(CasError):
    """A process of a run across processes went away, failed, or did not answer in time.

    A run failure (exit code 1), not a configuration error: the set-up was right,
    a process of it was not there.
    """


class WorkerRefused(WorkerLost):
    """A worker refused the run during set-up: the configuration fails on its host.

    Its app cannot be imported there, say, or its scenario is refused there: a
    configuration error (exit code 2), which the worker named.
    """


async def within(aw: Awaitable[T], seconds: float, what: str) -> T:
    """Awaits ``aw`` for at most ``seconds`` of wall time (a virtual loop's time may stand still).

    Raises:
        WorkerLost: the time ran out, naming ``what`` was awaited.
    """

    async def marked() -> object:
        return await aw

    result = await wall_bounded(marked(), seconds)
    if result is None:
        raise WorkerLost(f"gave up after {seconds:g} s waiting for {what}")
    return result  # type: ignore[return-value]
