"""The seed sweep: one scenario over two seeds, as a table and as JSON."""

from __future__ import annotations

import json

import pytest

from apps.fire_brigade.sweep import SweepRow, main, sweep, sweep_table
from tests.fire_brigade.helpers import SCENARIOS

SCENARIO = str(SCENARIOS / "thesis_5_8_2.toml")
SMALL = ["--seeds", "2", "--set", "mission.buckets=4"]


@pytest.fixture(scope="module")
def row() -> SweepRow:
    return sweep(SCENARIO, 2, ["mission.buckets=4"])


def test_sweep_summarises_every_seed(row: SweepRow) -> None:
    assert (row.scenario, row.strategy, row.completed, row.runs) == ("thesis_5_8_2", "time", 2, 2)
    spans = [row.makespan_min, row.makespan_median, row.makespan_max, row.makespan_mean]
    figures = [row.makespan_std, row.handovers_mean, row.travel_mean]
    assert None not in spans
    assert None not in figures
    low, middle, high, mean = (float(v) for v in spans if v is not None)
    std, handovers, travel = (float(v) for v in figures if v is not None)
    assert 0 < low <= middle <= high
    # two seeds: the mean is the median is the midpoint
    assert mean == pytest.approx(middle) == pytest.approx((low + high) / 2)
    assert std >= 0
    assert handovers >= 2
    assert travel > 0
    assert row.wall > 0


def test_sweep_table_has_one_line_per_scenario(row: SweepRow) -> None:
    lines = sweep_table([row, row]).splitlines()
    assert "makespan" in lines[0]
    assert lines[1].split() == [
        "scenario", "strategy", "runs", "mean", "std", "min", "median", "max",
        "hand-overs", "travel", "wall", "s",
    ]  # fmt: skip
    cells = lines[3].split()
    assert cells[:3] == ["thesis_5_8_2", "time", "2/2"]
    assert float(cells[3]) == pytest.approx(row.makespan_mean, abs=0.05)
    assert lines[3] == lines[4]


def test_cli_prints_the_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([SCENARIO, *SMALL]) == 0
    body = capsys.readouterr().out.splitlines()[3:]
    assert len(body) == 1
    assert body[0].split()[:3] == ["thesis_5_8_2", "time", "2/2"]


def test_cli_prints_json_per_scenario(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([SCENARIO, *SMALL, "--json", "--set", "strategy.name=solo"]) == 0
    (line,) = capsys.readouterr().out.splitlines()
    data = json.loads(line)
    assert set(data) == set(SweepRow.__dataclass_fields__)
    assert (data["strategy"], data["completed"], data["runs"]) == ("solo", 2, 2)
    assert data["handovers_mean"] == 2.0  # solo: generator -> transporter -> sink


def test_invalid_override_exits_with_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([SCENARIO, "--seeds", "1", "--set", "mission.buckets=0"]) == 2
    assert "mission.buckets" in capsys.readouterr().err


def test_runs_that_do_not_complete_are_named_not_averaged(
    capsys: pytest.CaptureFixture[str],
) -> None:
    row = sweep(SCENARIO, 1, ["mission.buckets=4", "run.max_time=1"])
    assert (row.completed, row.runs, row.makespan_mean, row.travel_mean) == (0, 1, None, None)
    assert row.incomplete == ("seed 1: timed_out",)
    assert sweep_table([row]).splitlines()[3].split()[2:5] == ["0/1", "n/a", "n/a"]
    assert main([SCENARIO, "--seeds", "1", "--set", "run.max_time=1"]) == 0
    assert capsys.readouterr().err == "thesis_5_8_2 seed 1: timed_out\n"
