"""What a run measured as it ended: its status on failure, the objective's figures, the rest.

The scenario runner calls these once, when the run ends (see
:class:`~cas_async.scenario.ScenarioRun`): the objective measures what the mission
was for, and these add what every run has (distances, messages, the app's measures
of the robots' positions).
"""

from __future__ import annotations

import math
import traceback

from ..sim._environment import Environment
from ._app import Mission
from ._objective import Objective
from ._results import RunResult, RunStatus
from ._trace import Trace

__all__ = ["mark_failed", "measure_end", "measure_positions"]


def mark_failed(result: RunResult, error: BaseException) -> None:
    """Marks the run failed, with the error and the traceback of what raised."""
    result.status, result.error = RunStatus.FAILED, str(error)
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
    """
    result.sim_time = now
    result.distance = {
        robot_id: travelled
        for robot_id, travelled in environment.distances(now).items()
        if environment.is_mobile(robot_id)
    }
    objective.measure(result, now)
    messages, errors = counts
    result.messages_internal = dict(sorted(messages["internal"].items()))
    result.messages_external = dict(sorted(messages["external"].items()))
    result.protocol_errors = dict(sorted(errors.items()))
    unanswered: dict[str, int] = {}
    for robot in mission.robots:  # none in a world process: its copies never start
        for what, n in robot.unanswered_requests().items():
            unanswered[what] = unanswered.get(what, 0) + n
    result.unanswered = dict(sorted(unanswered.items()))
    if mission.extra is not None:
        result.extra.update(mission.extra())


def measure_positions(result: RunResult, mission: Mission, trace: Trace) -> None:
    """Evaluates the mission's measures on every sample and snapshot of ``trace``."""
    ids, times = trace.ids, trace.times
    since = result.sim_time * 2 / 3  # the last third of the run
    for name, measure in mission.measures.items():
        values = [float(measure(ids, xy)) for xy in trace.positions]
        result.series[name] = {"t": times.tolist(), "value": values}
        late = [v for t, v in zip(times.tolist(), values, strict=True) if t >= since]
        if late:
            result.metrics[name] = math.fsum(late) / len(late)
        result.by_exchange[name] = {
            "count": [float(n) for n in trace.exchange_counts.tolist()],
            "value": [float(measure(ids, xy)) for xy in trace.exchange_positions],
        }
