"""A Fire Brigade run passing message objects is the run that encodes them, only faster."""

from __future__ import annotations

import pytest

from cas_async.scenario import RunStatus
from tests.fire_brigade.helpers import SCENARIOS, run_checked


@pytest.mark.parametrize("seed", [1, pytest.param(2, marks=pytest.mark.slow)])
def test_passing_objects_gives_the_same_run_as_bytes(seed: int) -> None:
    scenario = SCENARIOS / "thesis_5_8_2.toml"
    as_bytes, _, _ = run_checked(scenario, [f"run.seed={seed}"])
    as_objects, _, _ = run_checked(scenario, [f"run.seed={seed}", "run.pass_objects=true"])
    assert as_objects.status is RunStatus.COMPLETED, as_objects.error
    assert as_objects.protocol_errors == {}
    assert as_objects.makespan == as_bytes.makespan
    assert as_objects.exchanges == as_bytes.exchanges
    assert as_objects.messages_external == as_bytes.messages_external
