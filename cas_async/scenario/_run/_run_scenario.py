"""A whole run as one coroutine, to embed in any asyncio program."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from typing import TextIO

from ..._wire._swarm_key import SwarmKey
from ...sim._environment import Environment
from .._spec._loader import Scenario
from ..output._results import RunResult
from ..output._trace import Trace
from ._runner import ScenarioRun

__all__ = ["run_scenario"]


async def run_scenario(
    scenario: Scenario,
    *,
    progress_to: TextIO | None = None,
    stop: asyncio.Event | None = None,
    observe: Callable[[Environment], None] | None = None,
    wall_clock: Callable[[], float] = time.perf_counter,
    key: SwarmKey | None = None,
) -> tuple[RunResult, Trace]:
    """Runs ``scenario`` to its end and returns what it measured and the position trace.

    Run it on the loop the scenario needs: ``cas_async.run(run_scenario(s),
    virtual=s.run.virtual)``. While the swarm runs, the garbage collector's
    youngest generation is sized to the swarm (see :mod:`.gc_policy`): the
    process-wide threshold is raised for thousands of robots, then restored.
    The arguments are :class:`ScenarioRun`'s (all but ``trace_csv``: the trace is
    returned), which takes the same steps one by one.
    """
    run = ScenarioRun(
        scenario,
        key=key,
        progress_to=progress_to,
        stop=stop,
        observe=observe,
        wall_clock=wall_clock,
    )
    async with run:
        await run.until_done()
    return run.result, run.trace
