"""A whole scenario file run from a plain test, on its own loop."""

from __future__ import annotations

import asyncio
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from .. import run as run_loop
from ..scenario import RunResult, ScenarioRun, load_scenario
from ..scenario.output import Trace
from ..sim import Environment

__all__ = ["ScenarioOutcome", "run_scenario_file"]


@dataclass(frozen=True)
class ScenarioOutcome:
    """What :func:`run_scenario_file` ran: the result, the trace, and the world at the end.

    Attributes:
        result: what the run measured (``results.json``'s figures).
        trace: where the robots were over simulated time.
        environment: the simulated world as the run left it (its item ledger too).
    """

    result: RunResult
    trace: Trace
    environment: Environment


def run_scenario_file(
    path: str | os.PathLike[str],
    *overrides: str,
    virtual: bool = True,
    observe: Callable[[Environment], None] | None = None,
) -> ScenarioOutcome:
    """Loads a scenario file, runs it to its end, and returns what it measured.

    On virtual time with the in-memory transport by default (fast, and the same
    seed gives the same run); ``overrides`` are ``--set`` strings
    (``"strategy.name=solo"``). For a plain (synchronous) test: it runs its own
    event loop.

    Args:
        path: the scenario file.
        overrides: ``KEY=VALUE`` settings, applied after the file's.
        virtual: run on virtual time with the memory transport (``run.virtual``,
            ``run.transport``); ``False`` runs the file's own settings.
        observe: called with the Environment before the robots start.

    Raises:
        cas_async.scenario.ScenarioError: the file or an override is wrong.
        RuntimeError: called from a running event loop (await
            ``cas_async.scenario.run_scenario`` there instead).
    """
    settings = ["run.virtual=true", 'run.transport="memory"'] if virtual else []
    scenario = load_scenario(Path(path), [*settings, *overrides])

    async def run() -> ScenarioOutcome:
        scenario_run = ScenarioRun(scenario, observe=observe)
        async with scenario_run:
            await scenario_run.until_done()
        return ScenarioOutcome(scenario_run.result, scenario_run.trace, scenario_run.environment)

    try:
        asyncio.get_running_loop()
    except RuntimeError:
        pass
    else:
        raise RuntimeError(
            "run_scenario_file runs its own event loop: in an async test, "
            "await cas_async.scenario.run_scenario(load_scenario(...)) instead"
        )
    outcome: ScenarioOutcome = run_loop(run(), virtual=scenario.run.virtual)
    return outcome
