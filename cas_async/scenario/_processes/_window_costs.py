"""What a run across processes spent on its windows: the figures its ``results.json`` reports.

Kept by the world (see :mod:`._world`) from what its workers report: each
:class:`~._control.Window` (its cross-process effects, and how long the worker
was busy running it), and each worker's :class:`~._control.Bye` (how long it
waited). Every window ends for everyone when its slowest worker is done, so the
sum over windows of the busiest worker's time (``window_busy_max_s``) against
that of the average worker (``window_busy_mean_s``) is what the shared barrier
costs: their ratio is the load imbalance, window by window, that more workers do
not remove.
"""

from __future__ import annotations

from collections.abc import Collection
from typing import final

from ._control import Window

__all__ = ["WindowCosts"]


@final
class WindowCosts:
    """Window by window, what the workers report (see the module docs)."""

    def __init__(self) -> None:
        self.rounds = 0
        """Windows closed so far (virtual time)."""
        self.effects = 0
        """Effects (datagrams, hand-over steps) from a worker's robots to another's."""
        self._observing = 0.0  # wall seconds the world spent observing windows
        self._busy_mean = 0.0  # per window, the workers' mean busy time: summed
        self._busy_max = 0.0  # per window, the busiest worker's: summed
        self._waited: dict[int, tuple[float, float]] = {}  # a worker -> its Bye's waits
        self._spread: dict[int, tuple[float, float]] = {}  # a worker -> depended on, watched

    def flowed(self, window: Window) -> None:
        """Scaled time: a worker's records so far."""
        self.effects += len(window.remote)

    def closed(self, windows: Collection[Window], observing: float) -> None:
        """Every worker's window of one round, which the world took ``observing`` s to observe."""
        self.rounds += 1
        self._observing += observing
        self.effects += sum(len(window.remote) for window in windows)
        busy = [window.busy for window in windows]
        if busy:  # a world has at least one worker
            self._busy_mean += sum(busy) / len(busy)
            self._busy_max += max(busy)

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
        return {
            "workers": workers,
            "windows": self.rounds,
            "cross_process_effects": self.effects,
            "worker_waited_s": max((w for w, _ in self._waited.values()), default=0.0),
            "worker_waited_grant_s": max((g for _, g in self._waited.values()), default=0.0),
            "world_observing_s": round(self._observing, 3),
            "window_busy_mean_s": round(self._busy_mean, 3),
            "window_busy_max_s": round(self._busy_max, 3),
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
