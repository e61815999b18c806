"""The trace ends where the mission did: a last sample at the instant it completed."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

import cas_async
from cas_async.scenario import RunStatus, ScenarioRun, load_scenario

ROOT = Path(__file__).resolve().parents[2]
GATHERING = ROOT / "examples" / "gathering" / "gathering.toml"
FIRE_BRIGADE = ROOT / "apps" / "fire_brigade" / "scenarios" / "thesis_5_8_1.toml"


@pytest.mark.parametrize(
    ("path", "overrides"),
    [
        pytest.param(GATHERING, [], id="objective-of-its-own"),
        pytest.param(
            FIRE_BRIGADE,
            ["run.virtual=true", 'run.transport="memory"', "mission.buckets=5"],
            id="items",
        ),
    ],
)
def test_the_last_sample_is_at_the_completion_instant(
    tmp_path: Path, path: Path, overrides: list[str]
) -> None:
    scenario = load_scenario(path, overrides)
    csv_path = tmp_path / "trace.csv"
    completed: list[np.ndarray] = []

    async def main() -> ScenarioRun:
        run = ScenarioRun(scenario, trace_csv=csv_path)
        async with run:
            result = await run.until_done()
            assert result.makespan is not None
            completed.append(run.environment.positions_at(result.makespan).xy.copy())
        return run

    run = cas_async.run(main(), virtual=True)
    result, trace = run.result, run.trace
    assert result.status is RunStatus.COMPLETED
    assert result.makespan is not None
    assert result.makespan % scenario.run.trace_interval != 0  # else a tick would be there anyway
    assert trace.times[-1] == result.makespan
    assert trace.times[-2] < result.makespan  # the regular samples stopped short of it
    np.testing.assert_array_equal(trace.positions[-1], completed[0])
    with csv_path.open() as stream:
        last = list(csv.DictReader(stream))[-1]
    assert float(last["t"]) == result.makespan
