"""What a run tells a listener as it goes: its samples, its progress, and a pause after each sample.

A :class:`RunListener` is added with :meth:`ScenarioRun.listen
<cas_async.scenario.ScenarioRun.listen>` before the robots start. The live view
(:mod:`cas_async.live`) is one; a program may add its own (a publisher to
another robotics tool, a dashboard).

* :meth:`RunListener.sampled` is called by the run's sampler with every sample it
  records into the trace (the rows of ``trace.csv``), with the same arrays;
* :meth:`RunListener.changed` whenever the objective's progress changed;
* :meth:`RunListener.hold` is awaited by the sampler right after each sample,
  before it lets the run go on: the place to pace a run on virtual time against
  the wall clock. The robots' own logic never waits on it, so a run's results
  are the same with or without a listener.

Every call happens on the run's event loop; none may raise (an exception fails
the run, as a failed sample does).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
import numpy.typing as npt

__all__ = ["Listeners", "RunListener"]


class RunListener(Protocol):
    """Follows a run as it goes (see the module docs)."""

    def sampled(
        self, t: float, xy: npt.NDArray[np.float64], carrying: npt.NDArray[np.bool_]
    ) -> None:
        """Sample ``t``: ``xy`` (shape ``(n, 2)``) and ``carrying`` (shape ``(n,)``) are read-only.

        Rows follow the trace's robot order (``run.trace.ids``); the arrays are
        the ones the trace recorded, and stay valid after the call.
        """

    def changed(self, t: float) -> None:
        """The objective's progress changed at simulated instant ``t``."""

    async def hold(self, t: float) -> None:
        """Awaited right after sample ``t``; the run goes on when it returns."""


class Listeners:
    """The listeners of one run, called in the order they were added (internal)."""

    __slots__ = ("_listeners",)

    def __init__(self) -> None:
        self._listeners: list[RunListener] = []

    def add(self, listener: RunListener) -> None:
        """Adds ``listener`` after the others."""
        self._listeners.append(listener)

    def __bool__(self) -> bool:
        return bool(self._listeners)

    def sampled(
        self, t: float, xy: npt.NDArray[np.float64], carrying: npt.NDArray[np.bool_]
    ) -> None:
        """Tells every listener of sample ``t`` (the arrays are made read-only first)."""
        if not self._listeners:
            return
        carrying.flags.writeable = False
        for listener in self._listeners:
            listener.sampled(t, xy, carrying)

    def changed(self, t: float) -> None:
        """Tells every listener that progress changed."""
        for listener in self._listeners:
            listener.changed(t)

    async def hold(self, t: float) -> None:
        """Awaits every listener's hold, one after the other."""
        for listener in self._listeners:
            await listener.hold(t)
