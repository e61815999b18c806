"""What a run measured as it ended: its status on failure, the objective's figures, the rest.

The scenario runner calls these once, when the run ends (see
:class:`~cas_async.scenario.ScenarioRun`): the objective measures what the mission
was for, and these add what every run has (distances, messages, the app's measures
of the robots' positions).
"""

from __future__ import annotations

import math
import traceback
from collections.abc import Callable, Mapping, Sequence

import numpy as np
import numpy.typing as npt

from ...sim._environment import Environment
from .._processes._lost import WorkerLost
from .._spec._app import Mission
from .._spec._objective import Objective
from ..output._results import ExtraValueError, RunResult, RunStatus
from ..output._trace import Trace

__all__ = ["PositionMeasures", "mark_failed", "measure_end"]


def mark_failed(result: RunResult, error: BaseException) -> None:
    """Marks the run failed, with the error and the traceback of what raised.

    A lost worker has none: the error names the worker and its robots, and the
    world's own stack, where the loss was noticed, says nothing more.
    """
    result.status, result.error = RunStatus.FAILED, str(error)
    if isinstance(error, WorkerLost):
        result.traceback = None
        return
    cause = error.__cause__ or error
    result.traceback = "".join(traceback.format_exception(cause)).rstrip()


def measure_end(
    result: RunResult,
    mission: Mission,
    objective: Objective,
    counts: tuple[dict[str, dict[str, int]], dict[str, int]],
    environment: Environment,
    now: float,
) -> None:
    """Measures the run as it ended: the objective's figures, distances, messages, requests.

    The requests are the internal ones still unanswered (see
    :meth:`~cas_async.Robot.unanswered_requests`), read before the robots stop.
    The app's own measuring (the objective's ``measure``, the mission's ``extra``)
    that raises fails the run with one line saying where (see :func:`_app_measures`),
    and what was measured besides is kept.
    """
    result.sim_time = now
    result.distance = {
        robot_id: travelled
        for robot_id, travelled in environment.distances(now).items()
        if environment.is_mobile(robot_id)
    }
    measured_by = f"{type(objective).__name__}.measure"
    _app_measures(result, measured_by, lambda: objective.measure(result, now))
    messages, errors = counts
    result.messages_internal = dict(sorted(messages["internal"].items()))
    result.messages_external = dict(sorted(messages["external"].items()))
    result.protocol_errors = dict(sorted(errors.items()))
    unanswered: dict[str, int] = {}
    for robot in mission.robots:  # none in a world process: its copies never start
        for what, n in robot.unanswered_requests().items():
            unanswered[what] = unanswered.get(what, 0) + n
    result.unanswered = dict(sorted(unanswered.items()))
    extra = mission.extra
    if extra is not None:
        _app_measures(result, "Mission.extra", lambda: _extras_of(extra, result))


def _extras_of(extra: Callable[[], object], result: RunResult) -> None:
    figures = extra()
    if not isinstance(figures, Mapping):
        raise ExtraValueError(
            f"Mission.extra returned a {type(figures).__name__}, not a dict of figures by name"
        )
    result.extra.update(figures)


def _app_measures(result: RunResult, where: str, measure: Callable[[], None]) -> None:
    """Calls the app's ``measure``; its error fails the run (the first failure stays).

    A value refused by ``RunResult.extra`` says all in its line; any other error
    is the app's bug, named by ``where``, with its traceback.
    """
    try:
        measure()
    except Exception as error:
        if result.status is RunStatus.FAILED:
            return  # the run failed already: that failure is what the run reports
        result.status = RunStatus.FAILED
        if isinstance(error, ExtraValueError):
            result.error, result.traceback = str(error), None
        else:
            result.error = f"{where} raised {type(error).__name__}: {error}"
            result.traceback = "".join(traceback.format_exception(error)).rstrip()


class PositionMeasures:
    """The mission's measures of the robots' positions, taken with each sample and snapshot.

    Evaluated as the trace takes them rather than all at the end, so that a run
    ending (a signal, with ten thousand robots) has nothing heavy left to do.
    """

    def __init__(self, mission: Mission, ids: Sequence[int]) -> None:
        self._mission = mission  # its measures as they are now (an embedder may set them)
        self._ids = ids
        self._samples: dict[str, list[float]] = {}
        self._snapshots: dict[str, list[float]] = {}

    def sampled(self, xy: npt.NDArray[np.float64]) -> None:
        """A regular sample was taken with these positions."""
        for name, measure in self._mission.measures.items():
            self._samples.setdefault(name, []).append(float(measure(self._ids, xy)))

    def exchanged(self, xy: npt.NDArray[np.float64]) -> None:
        """An exchange snapshot was taken with these positions."""
        for name, measure in self._mission.measures.items():
            self._snapshots.setdefault(name, []).append(float(measure(self._ids, xy)))

    def write(self, result: RunResult, trace: Trace) -> None:
        """The series, the last third's means and the values by exchange, into ``result``.

        A measure not taken with every sample and snapshot (set meanwhile) is
        evaluated on the trace now.
        """
        times = trace.times.tolist()
        since = result.sim_time * 2 / 3  # the last third of the run
        for name, measure in self._mission.measures.items():
            values = self._samples.get(name, [])
            if len(values) != len(times):
                values = [float(measure(self._ids, xy)) for xy in trace.positions]
            result.series[name] = {"t": times, "value": values}
            late = [v for t, v in zip(times, values, strict=True) if t >= since]
            if late:
                result.metrics[name] = math.fsum(late) / len(late)
            counts = trace.exchange_counts.tolist()
            by_exchange = self._snapshots.get(name, [])
            if len(by_exchange) != len(counts):
                by_exchange = [float(measure(self._ids, xy)) for xy in trace.exchange_positions]
            result.by_exchange[name] = {"count": [float(n) for n in counts], "value": by_exchange}
