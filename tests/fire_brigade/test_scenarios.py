"""Every shipped scenario runs to completion; buckets are never lost nor duplicated.

The scale scenarios above 25 Transporters are only load-checked here (test_config,
test_scale): they are for ``python -m benchmarks.scale``, and would make the suite slow.
"""

from __future__ import annotations

import pytest

from cas_async.scenario import RunStatus, load_scenario
from cas_async.sim import ItemEventKind
from tests.fire_brigade.helpers import SCENARIOS, run_checked

SHIPPED = sorted(path.name for path in SCENARIOS.glob("*.toml"))
THESIS = [name for name in SHIPPED if name.startswith("thesis_")]
SCALE = [name for name in SHIPPED if name.startswith("scale_")]
RUN = [*THESIS, "scale_25.toml"]  # in full; the larger scale_* only load


def test_the_thesis_scenarios_ship_with_each_strategy() -> None:
    assert [
        f"thesis_5_8_{n}{variant}.toml" for n in (1, 2) for variant in ("", "_random", "_solo")
    ] == THESIS
    assert sorted(THESIS + SCALE) == SHIPPED


@pytest.mark.parametrize("name", RUN)
def test_shipped_scenario_delivers_every_bucket(name: str) -> None:
    result, trace, audits = run_checked(SCENARIOS / name)
    assert result.status is RunStatus.COMPLETED, result.error
    assert result.delivered == result.target == 20
    assert result.makespan is not None
    assert 0 < result.makespan <= result.sim_time
    # Every delivered bucket went from a generator to a sink through at least one hand-over.
    assert len(result.travel_times) == 20
    assert min(result.travel_times) > 0
    assert min(result.handovers_per_item) >= 2  # generator -> transporter -> sink
    # With the network's latency a hand-over is an item sent, then taken or refused (and
    # back) on arrival; one may still travel when the mission is complete.
    assert audits[ItemEventKind.CREATED] == result.created
    assert audits[ItemEventKind.TRANSFERRED] == result.exchanges
    assert audits[ItemEventKind.RETIRED] == result.delivered
    arrived = audits[ItemEventKind.TRANSFERRED] + audits[ItemEventKind.REFUSED]
    assert arrived <= audits[ItemEventKind.SENT] <= arrived + 2
    assert audits[ItemEventKind.RETURNED] <= audits[ItemEventKind.REFUSED]
    assert result.protocol_errors == {}
    if load_scenario(SCENARIOS / name).run.trace_exchanges:
        assert trace.exchange_counts[-1] == result.exchanges
    else:
        assert len(trace.exchange_counts) == 0


@pytest.mark.slow  # a few seconds: the fast suite stays under 2 minutes
def test_same_seed_same_run() -> None:
    first, _, _ = run_checked(SCENARIOS / "thesis_5_8_1.toml", ["run.seed=7"])
    again, _, _ = run_checked(SCENARIOS / "thesis_5_8_1.toml", ["run.seed=7"])
    other, _, _ = run_checked(SCENARIOS / "thesis_5_8_1.toml", ["run.seed=8"])
    assert first.makespan == again.makespan
    assert first.travel_times == again.travel_times
    assert first.messages_external == again.messages_external
    assert first.distance != other.distance


@pytest.mark.parametrize("strategy", ["time", "time_gain", "sink_first", "random", "solo"])
@pytest.mark.parametrize(
    "seed", [0, *(pytest.param(seed, marks=pytest.mark.slow) for seed in range(1, 8))]
)
def test_bucket_invariant_over_seeds(strategy: str, seed: int) -> None:
    # A smaller mission keeps this table fast; the audit runs after every item event.
    result, _, audits = run_checked(
        SCENARIOS / "thesis_5_8_2.toml",
        [f"strategy.name={strategy}", f"run.seed={seed}", "mission.buckets=8"],
    )
    assert result.status is RunStatus.COMPLETED, result.error
    assert result.delivered == 8
    assert audits[ItemEventKind.CREATED] == result.created
    assert audits[ItemEventKind.TRANSFERRED] == result.exchanges


def test_solo_transporters_never_hand_over_to_each_other() -> None:
    result, _, _ = run_checked(SCENARIOS / "thesis_5_8_2_solo.toml")
    # generator -> transporter, transporter -> sink: exactly two hand-overs per bucket
    assert set(result.handovers_per_item) == {2}


def test_time_strategy_collaborates() -> None:
    result, _, _ = run_checked(SCENARIOS / "thesis_5_8_2.toml")
    assert max(result.handovers_per_item) > 2
