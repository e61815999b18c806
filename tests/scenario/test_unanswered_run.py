"""A run whose robots wait on requests nobody answers says so when it ends (issue 30, finding 5)."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest

from cas_async.scenario import RunStatus
from cas_async.scenario.output import summary_table, write_results
from cas_async.testing import run_scenario_file

SCENARIO = """
app = "tests.scenario.unanswered_app"
[run]
max_time = 100.0
[world]
width = 10
height = 10
"""


def test_the_run_reports_which_layer_asked_what_of_whom_and_how_often(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="cas_async")
    path = tmp_path / "unanswered.toml"
    path.write_text(SCENARIO)
    outcome = run_scenario_file(path)
    result = outcome.result
    assert result.status is RunStatus.TIMED_OUT
    assert result.unanswered == {"Asker(L0) asked Silent(L1) for GoTo": 6}  # 3 robots x 2
    table = summary_table(result)
    assert "unanswered requests   Asker(L0) asked Silent(L1) for GoTo 6" in table
    assert "get_intra_msg_reply returned None" in table
    data = json.loads(write_results(result, tmp_path).read_text())
    assert data["unanswered"] == {"Asker(L0) asked Silent(L1) for GoTo": 6}
    late = [r.getMessage() for r in caplog.records if "has waited 50 s" in r.getMessage()]
    assert len(late) == 6  # at t = 50 s, once per request
