"""What a sweep measured: a small record per run, and statistics per point and metric.

A run's figures are its :meth:`RunResult.scalars() <cas_async.scenario.RunResult.scalars>`:
whatever names they hold (the app's own among them) are tabulated, in the order
they are first seen. Statistics count the completed runs only; a value that is
not finite (an app's NaN) counts as missing.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

from ..output._results import RunStatus
from ._plan import SweepPlan

__all__ = ["MetricStats", "SweepOutcome", "SweepRun", "summarise"]


@dataclass(frozen=True, slots=True)
class SweepRun:
    """One finished run of a sweep: small and picklable, without its trace.

    Attributes:
        point: the run's point, an index into :attr:`SweepPlan.points`.
        seed: its seed.
        status: how it ended.
        error: why it failed (the run's error, or what a worker raised), else ``None``.
        scalars: its figures by name (see :meth:`RunResult.scalars`).
    """

    point: int
    seed: int
    status: RunStatus
    error: str | None
    scalars: Mapping[str, float]

    @property
    def completed(self) -> bool:
        """Whether the run reached the mission's target."""
        return self.status is RunStatus.COMPLETED


@dataclass(frozen=True, slots=True)
class MetricStats:
    """One metric over some runs; the figures are ``None`` when ``n`` is 0.

    Attributes:
        n: how many values.
        mean: their mean.
        std: their sample standard deviation (0 for one value).
        min: the smallest.
        median: the middle one (the mean of the two middle ones for an even ``n``).
        max: the largest.
    """

    n: int
    mean: float | None = None
    std: float | None = None
    min: float | None = None
    median: float | None = None
    max: float | None = None


def summarise(values: Iterable[float]) -> MetricStats:
    """The :class:`MetricStats` of the finite ``values``; NaN and infinities are left out."""
    kept = sorted(value for value in values if math.isfinite(value))
    if not kept:
        return MetricStats(0)
    return MetricStats(
        n=len(kept),
        mean=statistics.fmean(kept),
        std=statistics.stdev(kept) if len(kept) > 1 else 0.0,
        min=kept[0],
        median=statistics.median(kept),
        max=kept[-1],
    )


@dataclass(frozen=True, slots=True)
class SweepOutcome:
    """A sweep's runs, finished or not, and what they add up to.

    Attributes:
        plan: what was to run.
        runs: the runs that finished (completed or not), by point then seed; a
            resumed sweep's earlier runs among them.
        wall_time: wall seconds of the whole sweep (of this session, when resumed).
        jobs: how many runs were handed out at a time, at most.
        interrupted: the sweep ended before every run had finished.
        error: why it ended so when nobody stopped it (the connection to the
            cluster was lost, the executor failed), else ``None``.
        resumed: how many of :attr:`runs` an earlier session of the sweep had made.
        ran_on: where the runs ran, for people (``"2 worker processes"``,
            ``"2 Dask workers at tcp://10.0.0.5:8786"``); empty when not said.
        workers_lost: worker processes that died while the sweep ran.
        runs_resent: runs handed out again because their worker was lost.
    """

    plan: SweepPlan
    runs: tuple[SweepRun, ...]
    wall_time: float
    jobs: int
    interrupted: bool = False
    error: str | None = None
    resumed: int = 0
    ran_on: str = ""
    workers_lost: int = 0
    runs_resent: int = 0

    @property
    def incomplete(self) -> tuple[SweepRun, ...]:
        """The finished runs that did not complete (failed, timed out)."""
        return tuple(run for run in self.runs if not run.completed)

    @property
    def all_completed(self) -> bool:
        """Whether every planned run ran and completed."""
        return len(self.runs) == self.plan.runs and not self.incomplete

    @property
    def metrics(self) -> tuple[str, ...]:
        """Every figure's name, in the order first seen (by point, then seed)."""
        return tuple(dict.fromkeys(name for run in self.runs for name in run.scalars))

    def by_point(self) -> list[list[SweepRun]]:
        """The finished runs of each point (as :attr:`SweepPlan.points`), by seed."""
        groups: list[list[SweepRun]] = [[] for _ in self.plan.points]
        for run in self.runs:
            groups[run.point].append(run)
        return groups

    def statistics(self) -> list[dict[str, MetricStats]]:
        """Per point (as :attr:`SweepPlan.points`), per metric: over its completed runs."""
        metrics = self.metrics
        return [_point_statistics(runs, metrics) for runs in self.by_point()]


def _point_statistics(runs: Sequence[SweepRun], metrics: Sequence[str]) -> dict[str, MetricStats]:
    done = [run for run in runs if run.completed]
    return {
        name: summarise(run.scalars[name] for run in done if name in run.scalars)
        for name in metrics
    }
