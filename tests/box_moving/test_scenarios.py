"""The shipped scenarios end to end: objects moved alone and in pairs, the Floor audited all along.

On virtual time over the in-memory transport (one run over real UDP on scaled
time); the runner audits the Floor at every sample (the objective's check),
counted here, and the Floor checks every lift, put-down and lifter's motion.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from apps.box_moving.floor import Floor
from cas_async import run
from cas_async.scenario import RunResult, RunStatus, ScenarioRun, load_scenario
from cas_async.testing import ScenarioOutcome, run_scenario_file
from tests.box_moving.helpers import SCENARIOS

THESIS = SCENARIOS / "thesis_4_4.toml"


@pytest.fixture
def audits(monkeypatch: pytest.MonkeyPatch) -> list[float]:
    """The instants of every full audit of a Floor during the test."""
    instants: list[float] = []
    audit = Floor.audit

    def counted(floor: Floor, t: float) -> None:
        instants.append(t)
        audit(floor, t)

    monkeypatch.setattr(Floor, "audit", counted)
    return instants


def completed(outcome: ScenarioOutcome, target: int) -> RunResult:
    result = outcome.result
    assert result.status is RunStatus.COMPLETED, result.error
    assert result.delivered == result.target == target
    assert result.protocol_errors == {}
    return result


@pytest.mark.parametrize("seed", range(1, 6))
def test_the_thesis_scenario_moves_five_objects_alone_and_in_pairs(
    seed: int, audits: list[float]
) -> None:
    outcome = run_scenario_file(THESIS, f"run.seed={seed}")
    result = completed(outcome, 5)
    joint, solo = int(result.extra["joint_carries"]), int(result.extra["solo_carries"])
    assert joint >= 1
    assert solo >= 1
    assert joint + solo == 5
    assert result.extra["objects_left"] == 2
    assert result.makespan == result.delivery_times[-1]
    assert all(value > 0 for value in result.samples["time_per_object"])
    assert all(value > 0 for value in result.samples["carry_distance"])
    # a sample (and an audit) every 0.5 s, then one more sample where the mission completed
    assert len(audits) == len(outcome.trace.times) - 1 > result.makespan
    assert outcome.trace.times[-1] == result.makespan


def test_the_same_seed_makes_the_same_run_and_another_seed_another() -> None:
    first = run_scenario_file(THESIS, "run.seed=3").result
    again = run_scenario_file(THESIS, "run.seed=3").result
    other = run_scenario_file(THESIS, "run.seed=4").result
    assert first.delivery_times == again.delivery_times
    assert first.messages_external == again.messages_external
    assert first.makespan != other.makespan  # the robots' headings differ


def test_the_swapped_coordination_layer_balances_otherwise(audits: list[float]) -> None:
    default = completed(run_scenario_file(THESIS), 5)
    fixed = completed(run_scenario_file(SCENARIOS / "thesis_4_4_fixed.toml"), 5)
    assert fixed.extra["coordination"] == (
        "apps.box_moving.coordination_fixed.FixedSideCoordination"
    )
    assert default.extra["coordination"] == "apps.box_moving.coordination.Coordination"
    assert sum(fixed.distance.values()) > sum(default.distance.values())
    assert fixed.makespan is not None
    assert default.makespan is not None
    assert fixed.makespan > default.makespan
    assert audits


def test_the_warehouse_pairs_robots_up(audits: list[float]) -> None:
    outcome = run_scenario_file(SCENARIOS / "warehouse.toml")
    result = completed(outcome, 15)
    assert int(result.extra["joint_carries"]) >= 5
    assert len({robot for robot, travelled in result.distance.items() if travelled > 0}) == 8
    assert len(audits) == len(outcome.trace.times) - 1  # not at the completion's sample


@pytest.mark.slow
def test_the_thesis_scenario_runs_over_udp_on_scaled_time() -> None:
    outcome = run_scenario_file(THESIS, "run.time_factor=50", virtual=False)
    assert load_scenario(THESIS).run.transport == "udp"
    result = outcome.result
    assert result.status is RunStatus.COMPLETED, result.error
    assert result.delivered == result.target == 5
    # On a loaded machine a reply may come after its request's timeout, and the
    # request goes again: both copies arrive, the second is dropped as a
    # duplicate (that is the runtime doing its job). Anything else is a fault.
    assert set(result.protocol_errors) <= {"duplicate", "late_reply", "duplicate_reply"}


def test_the_objects_figure_is_drawn(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    scenario = load_scenario(THESIS, ["run.virtual=true", 'run.transport="memory"'])

    async def go() -> list[Path]:
        scenario_run = ScenarioRun(scenario)
        async with scenario_run:
            await scenario_run.until_done()
        return scenario_run.objective.figures(scenario_run.trace, tmp_path)

    (figure,) = run(go(), virtual=True)
    assert figure.name == "objects.png"
    assert figure.stat().st_size > 10_000
