"""On scaled real time a run says how far it fell behind the wall clock (``behind_s``)."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

import cas_async
from cas_async.scenario import RunResult, RunStatus, ScenarioRun, load_scenario
from cas_async.scenario.output import summary_table

ROOT = Path(__file__).resolve().parents[2]
GATHERING = ROOT / "examples" / "gathering" / "gathering.toml"


def _run(overrides: list[str], *, block_s: float, virtual: bool) -> RunResult:
    """Gathering, with the loop blocked for ``block_s`` wall seconds once it has started."""
    scenario = load_scenario(GATHERING, overrides)

    async def main() -> RunResult:
        run = ScenarioRun(scenario)
        async with run:
            await asyncio.sleep(0)  # the robots have started
            time.sleep(block_s)  # noqa: ASYNC251 - a stalled loop: the samples due come late
            return await run.until_done()

    return cas_async.run(main(), virtual=virtual)


def test_a_stalled_scaled_run_says_how_far_it_fell_behind() -> None:
    # At 10 simulated seconds per second, a loop stalled 0.3 wall s is 3 simulated
    # seconds late: the next sample (every 0.5 s) comes at least 2.5 s after its instant.
    result = _run(
        ["run.virtual=false", "run.time_factor=10", "run.trace_interval=0.5"],
        block_s=0.3,
        virtual=False,
    )
    assert result.status is RunStatus.COMPLETED
    assert result.extra["behind_s"] >= 2.5
    assert "fell behind" in summary_table(result)


def test_a_virtual_run_is_never_behind() -> None:
    result = _run([], block_s=0.0, virtual=True)
    assert result.status is RunStatus.COMPLETED
    assert "behind_s" not in result.extra
    assert "fell behind" not in summary_table(result)
