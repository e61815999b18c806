"""What a run across processes spent on its windows: the figures its ``results.json`` reports.

Kept by the world (see :mod:`._world`) from what its workers report: each
:class:`~._control.Window` (its cross-process effects, and how long the worker
was busy running it), and each worker's :class:`~._control.Bye` (how long it
waited). Each worker runs its own windows and waits only for the workers it
depends on; the busiest worker's busy time (``window_busy_max_s``) against the
average worker's (``window_busy_mean_s``) is the load imbalance: the busiest
one sets the pace of those that depend on it.
"""

from __future__ import annotations

from typing import final

from ._control import Window

__all__ = ["WindowCosts"]


@final
class WindowCosts:
    """Window by window, what the workers report (see the module docs)."""

    def __init__(self) -> None:
        self.effects = 0
        """Effects (datagrams, hand-over steps) from a worker's robots to another's."""
        self._observing = 0.0  # wall seconds the world spent observing windows
        self._windows: dict[int, int] = {}  # a worker -> windows it closed
        self._busy: dict[int, float] = {}  # a worker -> wall seconds busy in them, summed
        self._waited: dict[int, tuple[float, float]] = {}  # a worker -> its Bye's waits
        self._spread: dict[int, tuple[float, float]] = {}  # a worker -> depended on, watched

    @property
    def rounds(self) -> int:
        """The most windows a worker closed so far (virtual time)."""
        return max(self._windows.values(), default=0)

    def flowed(self, window: Window) -> None:
        """Scaled time: a worker's records so far."""
        self.effects += len(window.remote)

    def window(self, worker: int, window: Window) -> None:
        """A worker closed a window (virtual time)."""
        self._windows[worker] = self._windows.get(worker, 0) + 1
        self._busy[worker] = self._busy.get(worker, 0.0) + window.busy
        self.effects += len(window.remote)

    def observed(self, seconds: float) -> None:
        """The world took ``seconds`` (wall) to observe what came in."""
        self._observing += seconds

    def waited(self, worker: int, waited: float, for_grant: float) -> None:
        """A worker's wall seconds waiting, as its :class:`~._control.Bye` says."""
        self._waited[worker] = (waited, for_grant)

    def spread(self, worker: int, dependencies: float, watched: float) -> None:
        """A worker's mean dependency set and robots watched, as its ``Bye`` says (a range)."""
        self._spread[worker] = (dependencies, watched)

    def stats(self, workers: int, *, virtual: bool) -> dict[str, float | int | str]:
        """The figures of ``results.json`` (see :meth:`World.stats <._world.World.stats>`)."""
        if not virtual:
            return {"workers": workers, "cross_process_effects": self.effects}
        busy = list(self._busy.values())
        return {
            "workers": workers,
            "windows": self.rounds,
            "cross_process_effects": self.effects,
            "worker_waited_s": max((w for w, _ in self._waited.values()), default=0.0),
            "worker_waited_grant_s": max((g for _, g in self._waited.values()), default=0.0),
            "world_observing_s": round(self._observing, 3),
            "window_busy_mean_s": round(sum(busy) / len(busy), 3) if busy else 0.0,
            "window_busy_max_s": round(max(busy, default=0.0), 3),
            **self._spreads(),
        }

    def _spreads(self) -> dict[str, float]:
        """With an interaction range: how many workers each depended on, and robots it watched."""
        spread = [value for value in self._spread.values() if value != (0.0, 0.0)]
        if not spread:
            return {}
        return {
            "dependency_set_mean": round(sum(d for d, _ in spread) / len(spread), 2),
            "watched_robots_mean": round(sum(w for _, w in spread) / len(spread), 1),
        }
