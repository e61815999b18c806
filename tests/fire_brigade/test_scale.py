"""What the Fire Brigade needs at scale: shared peer lists, repeated stations, nearby sink search.

The scale scenarios themselves are load-checked here (and ``scale_25`` run in full
by test_scenarios); the large ones are for ``python -m benchmarks.scale``.
"""

from __future__ import annotations

import io
import sys
from pathlib import Path

import pytest

from apps.fire_brigade.base import Peers
from apps.fire_brigade.config import FireBrigadeConfig, Stations
from apps.fire_brigade.messages import Kind
from cas_async import LayerError
from cas_async._cli._main import main
from cas_async.scenario import RunStatus, ScenarioError, load_scenario
from tests.fire_brigade.helpers import SCENARIOS, run_checked
from tests.fire_brigade.test_layers import NORTH, SOUTH, Brigade, Spot, play

GENERATOR, SINK, TRANSPORTER = Kind.GENERATOR, Kind.SINK, Kind.TRANSPORTER
SCALE = sorted(SCENARIOS.glob("scale_*.toml"))


# -- Peers --------------------------------------------------------------------------------


@pytest.mark.parametrize("at", [0, 2, 4])
def test_peers_are_the_roster_without_one_robot(at: int) -> None:
    roster = (10, 20, 30, 40, 50)
    expected = tuple(r for k, r in enumerate(roster) if k != at)
    peers = Peers(roster, at)
    assert len(peers) == 4
    assert tuple(peers) == expected
    assert [peers[k] for k in range(-4, 4)] == [*expected, *expected]
    assert peers[1:3] == expected[1:3]
    assert peers == expected
    assert expected == peers
    assert peers != expected[:3]
    assert hash(peers) == hash(expected)
    assert roster[at] not in peers
    assert all(r in peers for r in expected)
    assert 99 not in peers


def test_peers_share_the_roster_instead_of_copying_it() -> None:
    roster = tuple(range(1, 10_001))
    everyone = [Peers(roster, at) for at in range(len(roster))]
    assert all(peers._roster is roster for peers in everyone)
    assert sys.getsizeof(everyone[0]) < 100


def test_peers_refuse_a_position_outside_the_roster() -> None:
    with pytest.raises(IndexError, match="position 3 is not in a roster of 3 robots"):
        Peers((1, 2, 3), 3)
    with pytest.raises(IndexError, match="peer index 2 out of range for 2 peers"):
        Peers((1, 2, 3), 0)[2]


# -- repeated stations ------------------------------------------------------------------------


def test_stations_repeat_copy_by_copy_in_listed_order() -> None:
    stations = Stations(generators=((4.0, 0.0), (8.0, 0.0)), repeat=3, repeat_offset=(10.0, 1.0))
    assert stations.placed(stations.generators) == (
        (4.0, 0.0), (8.0, 0.0), (14.0, 1.0), (18.0, 1.0), (24.0, 2.0), (28.0, 2.0),
    )  # fmt: skip
    assert Stations().placed(Stations().sinks) == Stations().sinks


def test_a_copy_outside_the_world_is_named() -> None:
    base = SCENARIOS / "thesis_5_8_1.toml"
    with pytest.raises(ScenarioError) as caught:
        load_scenario(base, ["stations.repeat=2"])
    problems = dict(caught.value.problems)
    assert problems["stations.generators[0]"] == (
        "expected a position inside the world (0..10, 0..10), got [14, 0] (copy 2 of 2)"
    )
    assert set(problems) == {
        f"stations.{kind}[{k}]" for kind in ("generators", "sinks") for k in (0, 1)
    }
    with pytest.raises(ScenarioError, match="two stations stand at the same position"):
        load_scenario(base, ["stations.repeat=2", "stations.repeat_offset=[0.0, 0.0]"])


# -- the scale scenarios ------------------------------------------------------------------------


def test_the_scale_scenarios_ship_for_each_count() -> None:
    assert [path.name for path in SCALE] == [
        f"scale_{n}.toml" for n in sorted((25, 250, 2500, 10000), key=str)
    ]


@pytest.mark.parametrize("path", SCALE, ids=[path.stem for path in SCALE])
def test_a_scale_scenario_repeats_the_thesis_cell_once_per_25_transporters(path: object) -> None:
    scenario = load_scenario(path)  # type: ignore[arg-type]
    config = scenario.config
    assert isinstance(config, FireBrigadeConfig)
    count = int(scenario.path.stem.removeprefix("scale_"))
    cells = count // 25
    assert config.transporters.count == count
    assert config.stations.repeat == cells
    assert len(config.stations.placed(config.stations.generators)) == 2 * cells
    assert len(config.stations.placed(config.stations.sinks)) == 2 * cells
    assert config.mission.buckets == 20 * cells
    assert (scenario.world.width, scenario.world.height) == (10.0 * cells, 10.0)
    assert config.transporters.spawn_max == (10.0 * cells - 1, 7.0)
    assert (scenario.run.virtual, scenario.run.transport) == (True, "memory")
    assert not scenario.run.trace_exchanges
    assert config.strategy.sink_search == "nearby"
    assert config.transporters.speed == 3.0  # the rest is §5.8.2


def test_without_exchange_snapshots_the_trace_has_only_samples() -> None:
    result, trace, _ = run_checked(
        SCENARIOS / "thesis_5_8_2.toml", ["mission.buckets=4", "run.trace_exchanges=false"]
    )
    assert result.status is RunStatus.COMPLETED, result.error
    assert result.exchanges > 0
    assert len(trace.exchange_counts) == 0
    assert len(trace.times) > 0


@pytest.mark.slow
def test_the_cli_says_the_exchange_figure_is_empty_because_snapshots_were_off(
    tmp_path: Path, plot_notes: list[str]
) -> None:
    argv = ["run", str(SCENARIOS / "thesis_5_8_2.toml"), "--virtual", "--out", str(tmp_path)]
    argv += ["--set", "mission.buckets=2", "--set", "run.trace_exchanges=false"]
    assert main(argv, stdout=io.StringIO(), stderr=io.StringIO()) == 0
    assert (tmp_path / "snapshots_by_exchange.png").exists()
    assert plot_notes == ["exchange snapshots switched off\n([run] trace_exchanges = false)"]


# -- finding the Sinks nearby -------------------------------------------------------------------


def test_a_generator_looking_nearby_widens_until_a_sink_answers() -> None:
    spots = [
        Spot(1, GENERATOR, 8.0, 1.0, NORTH),
        Spot(2, SINK, 1.0, 9.0, SOUTH),  # 10.6 away
        Spot(3, SINK, 9.0, 9.0, SOUTH),  # 8.06 away
        Spot(4, TRANSPORTER, 8.0, 0.0, NORTH),  # 1 away
        Spot(5, TRANSPORTER, 1.0, 0.0, NORTH),  # 7 away
    ]

    async def main() -> Brigade:
        async with Brigade(spots, range=3.0, sink_search="nearby") as b:
            await b.until(lambda: b.delivered == 1, within=30.0)
        return b

    b = play(main)
    goal = b.layer(1, 0)
    # Radius 3: robot 4 only, not a Sink; 6: nobody new; 12: both Sinks and robot 5.
    assert goal.radius == 12.0
    assert goal.sinks == {2: (1.0, 9.0), 3: (9.0, 9.0)}
    assert b.path(1)[-1] == 3  # the nearest


def test_a_generator_looking_nearby_stops_at_the_first_radius_with_a_sink() -> None:
    spots = [
        Spot(1, GENERATOR, 5.0, 1.0, NORTH),
        Spot(2, SINK, 5.0, 5.0, SOUTH),  # 4 away
        Spot(3, SINK, 5.0, 9.9, SOUTH),  # 8.9 away: never asked
        Spot(4, TRANSPORTER, 5.0, 0.0, NORTH),
    ]

    async def main() -> Brigade:
        async with Brigade(spots, range=5.0, sink_search="nearby") as b:
            await b.until(lambda: b.delivered == 1, within=30.0)
        return b

    b = play(main)
    assert b.layer(1, 0).sinks == {2: (5.0, 5.0)}
    assert b.layer(1, 0).radius == 5.0


def test_a_sink_beyond_range_is_found_by_widening() -> None:
    result, _, _ = run_checked(
        SCENARIOS / "thesis_5_8_2.toml",
        ['strategy.sink_search="nearby"', "stations.sinks=[[9.5, 9.5]]", "mission.buckets=2"],
    )
    assert result.status is RunStatus.COMPLETED, result.error
    assert result.delivered == 2


def test_a_swarm_without_a_sink_fails_the_nearby_search_by_name() -> None:
    spots = [Spot(1, GENERATOR, 5.0, 1.0, NORTH), Spot(2, TRANSPORTER, 5.0, 0.0, NORTH)]

    async def main() -> None:
        async with Brigade(spots, sink_search="nearby") as b:
            await b.until(lambda: False, within=5.0)

    with pytest.raises(LayerError, match="no robot of the swarm is a sink"):
        play(main)


@pytest.mark.parametrize(
    "strategy", ["time", pytest.param("random", marks=pytest.mark.slow), "solo"]
)
def test_three_thesis_cells_looking_nearby_deliver_with_fewer_questions(strategy: str) -> None:
    # Three copies of the §5.8.2 world side by side: every Generator's nearest Sink is
    # in its own cell, 9 away; asking only within 10 leaves the far cell out.
    common = [
        f"strategy.name={strategy}",
        "mission.buckets=8",
        "world.width=30",
        "stations.repeat=3",
        "transporters.spawn_max=[29.0, 7.0]",
    ]
    everyone, _, _ = run_checked(SCENARIOS / "thesis_5_8_2.toml", common)
    nearby, _, _ = run_checked(
        SCENARIOS / "thesis_5_8_2.toml", [*common, 'strategy.sink_search="nearby"']
    )
    assert everyone.status is nearby.status is RunStatus.COMPLETED, nearby.error
    assert nearby.delivered == everyone.delivered == 8
    asked = nearby.messages_external["RequestInfo"]
    assert 2 * asked <= everyone.messages_external["RequestInfo"]
