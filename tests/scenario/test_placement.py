"""Where a run's robots run: the one placement each kind of scenario gets, and what it observes.

:func:`~cas_async.scenario._run._placement.place` chooses once; the run itself never
asks again. Each case builds the mission as a run does and checks the choice:
its kind, whether the run observes the robots' own Environment or a mirror, and
whose robots start in this process.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pytest

from cas_async import ConfigurationError
from cas_async.scenario import Scenario, load_scenario
from cas_async.scenario._processes._world import World
from cas_async.scenario._run._placement import (
    Placement,
    Sampled,
    Sampling,
    Windowed,
    WorkersFollowed,
    WorkersWindowed,
    place,
    transport_for,
)
from cas_async.scenario._spec._app import objective_of
from cas_async.sim import Environment
from tests.scenario.test_objectives import SCENARIO as CHORES

FIRE_BRIGADE = Path(__file__).resolve().parents[2] / "apps" / "fire_brigade" / "scenarios"
SMALL = FIRE_BRIGADE / "thesis_5_8_1.toml"
VIRTUAL = ("run.virtual=true", 'run.transport="memory"', "mission.buckets=4")
SCALED = ("run.time_factor=20", 'run.transport="memory"', "mission.buckets=4")


async def _held(t: float) -> None:
    del t


def placed(scenario: Scenario, world: World | None = None) -> tuple[Placement, Environment]:
    """The placement of ``scenario``'s mission, built as a run builds it; the Environment."""
    clock = scenario.clock()
    environment = scenario.environment(clock)
    transport = transport_for(scenario, clock, None, world, environment)
    mission = scenario.app.build(scenario.setup(environment, clock, transport))
    objective = objective_of(mission, scenario.app.name, "item")
    sampling = Sampling(
        clock=clock,
        max_time=scenario.run.max_time,
        interval=scenario.run.trace_interval,
        sample=lambda t: None,
        hold=_held,
        sample_held=_held,
        behind=lambda seconds: None,
        done=lambda: False,
    )
    return place(scenario, environment, transport, mission, objective, sampling, world), environment


def fire_brigade(*overrides: str) -> Scenario:
    return load_scenario(SMALL, overrides)


@pytest.mark.parametrize(
    ("overrides", "kind", "mirrored"),
    [
        ((*VIRTUAL, "network.latency=0"), Sampled, False),
        ((*VIRTUAL, "network.latency=0.005"), Windowed, True),
        ((*SCALED, "network.latency=0.005"), Sampled, False),
        ((*SCALED, "network.latency=0"), Sampled, False),
    ],
    ids=["virtual", "virtual-latency", "scaled-latency", "scaled"],
)
def test_robots_in_this_process_are_sampled_or_run_in_windows(
    overrides: Sequence[str], kind: type, mirrored: bool
) -> None:
    placement, environment = placed(fire_brigade(*overrides))
    assert type(placement) is kind
    assert (placement.environment is not environment) is mirrored
    assert len(placement.swarm) == len(environment.robot_ids) > 0
    assert placement.observed_until() == (0.0 if mirrored else None)
    assert ("windows" in placement.stats()) is mirrored


def test_a_mission_of_its_own_runs_sampled_even_with_a_latency(tmp_path: Path) -> None:
    """An objective that is not distributable keeps its state here: no mirror to read."""
    path = tmp_path / "chores.toml"
    path.write_text(CHORES + "target = 3\n[network]\nlatency = 0.005\n")
    placement, environment = placed(load_scenario(path))
    assert type(placement) is Sampled
    assert placement.environment is environment


@pytest.mark.parametrize(
    ("overrides", "kind"),
    [
        (VIRTUAL, WorkersWindowed),
        (SCALED, WorkersFollowed),
    ],
    ids=["virtual", "scaled"],
)
def test_robots_in_workers_are_observed_in_a_mirror_and_none_start_here(
    overrides: Sequence[str], kind: type
) -> None:
    pytest.importorskip("zenoh")  # a World needs it importable; nothing is started here
    scenario = fire_brigade(*overrides)
    world = World(scenario, workers=2, key=None, spawn=False)
    placement, environment = placed(scenario, world)
    assert type(placement) is kind
    assert placement.environment is not environment
    assert sorted(placement.environment.robot_ids) == sorted(environment.robot_ids)
    assert len(placement.swarm) == 0
    assert [len(share) for share in world.shares] == [10, 10]  # thesis 5.8.1: 20 robots
    assert placement.stats()["workers"] == 2


def test_workers_refuse_a_mission_of_its_own(tmp_path: Path) -> None:
    pytest.importorskip("zenoh")
    path = tmp_path / "chores.toml"
    path.write_text(CHORES + "target = 3\n")
    scenario = load_scenario(path)
    world = World(scenario, workers=1, key=None, spawn=False)
    with pytest.raises(ConfigurationError, match="is not distributable"):
        placed(scenario, world)
