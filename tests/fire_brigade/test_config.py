"""The Fire Brigade's scenario checks (``FireBrigade.check``) and swarm building (``build``)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import pytest

from apps.fire_brigade import RandomStrategy, SoloStrategy, Strategy, TimeStrategy
from apps.fire_brigade.action import Action
from apps.fire_brigade.app import MESSAGES, FireBrigade
from apps.fire_brigade.config import FireBrigadeConfig, Stations, StrategyConfig, Transporters
from apps.fire_brigade.goal import Goal
from apps.fire_brigade.group_activity import GroupActivity
from apps.fire_brigade.messages import Kind
from apps.fire_brigade.strategies import STRATEGY_NAMES
from apps.fire_brigade.task import Task
from cas_async import MemoryTransport, VirtualClock
from cas_async.scenario import Mission, ScenarioError, SimulationSetup, load_scenario
from cas_async.sim import Environment
from tests.fire_brigade.helpers import SCENARIOS

SHIPPED = sorted(path.name for path in SCENARIOS.glob("*.toml"))
BASE = SCENARIOS / "thesis_5_8_1.toml"
WORLD = (10.0, 10.0)


def problems_of(
    overrides: Sequence[str], scenario: str = "thesis_5_8_1.toml"
) -> list[tuple[str, str]]:
    """The ``(key, message)`` problems ``load_scenario`` reports for ``scenario``."""
    with pytest.raises(ScenarioError) as caught:
        load_scenario(SCENARIOS / scenario, overrides)
    assert caught.value.file == str(SCENARIOS / scenario)
    return list(caught.value.problems)


def keys_of(overrides: Sequence[str], scenario: str = "thesis_5_8_1.toml") -> list[str]:
    return [key for key, _ in problems_of(overrides, scenario)]


# -- the shipped scenarios pass ------------------------------------------------------------


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_scenarios_pass_the_checks(name: str) -> None:
    scenario = load_scenario(SCENARIOS / name)
    assert isinstance(scenario.app, FireBrigade)
    assert isinstance(scenario.config, FireBrigadeConfig)
    assert scenario.config.strategy.name in STRATEGY_NAMES


@pytest.mark.parametrize(
    "overrides",
    [
        pytest.param(["stations.generators=[[0.0, 0.0], [10.0, 10.0]]"], id="stations-on-corners"),
        pytest.param(
            ["transporters.spawn_min=[0, 0]", "transporters.spawn_max=[10, 10]"],
            id="spawn-whole-world",
        ),
        pytest.param(
            ["transporters.spawn_min=[5, 5]", "transporters.spawn_max=[5, 5]"], id="spawn-one-point"
        ),
        pytest.param(["transporters.min_speed=5.0"], id="min-speed-equals-speed"),
        pytest.param(["strategy.name=apps.fire_brigade:RandomStrategy"], id="strategy-by-path"),
        pytest.param(["world.width=100", "stations.sinks=[[95, 9]]"], id="bigger-world"),
    ],
)
def test_borderline_values_are_accepted(overrides: list[str]) -> None:
    load_scenario(BASE, overrides)


# -- each mistake names its key ----------------------------------------------------------


@pytest.mark.parametrize(
    ("overrides", "key", "says"),
    [
        pytest.param(
            ["stations.generators=[[10.5, 0.0], [8.0, 0.0]]"],
            "stations.generators[0]",
            "got [10.5, 0]",
            id="generator-right-of-world",
        ),
        pytest.param(
            ["stations.generators=[[4.0, 0.0], [8.0, -0.1]]"],
            "stations.generators[1]",
            "inside the world (0..10, 0..10)",
            id="generator-below-world",
        ),
        pytest.param(
            ["stations.sinks=[[4.0, 9.0], [8.0, 10.01]]"],
            "stations.sinks[1]",
            "got [8, 10.01]",
            id="sink-above-world",
        ),
        pytest.param(
            ["transporters.spawn_min=[-1.0, 1.0]"],
            "transporters.spawn_min",
            "expected a corner inside the world",
            id="spawn-min-outside",
        ),
        pytest.param(
            ["transporters.spawn_max=[9.0, 12.0]"],
            "transporters.spawn_max",
            "expected a corner inside the world",
            id="spawn-max-outside",
        ),
        pytest.param(
            ["transporters.spawn_min=[9.0, 1.0]", "transporters.spawn_max=[3.0, 7.0]"],
            "transporters.spawn_max",
            "above and to the right of spawn_min [9.0, 1.0]",
            id="spawn-min-right-of-max",
        ),
        pytest.param(
            ["transporters.spawn_min=[3.0, 7.5]"],
            "transporters.spawn_max",
            "above and to the right",
            id="spawn-min-above-max",
        ),
        pytest.param(
            ["transporters.min_speed=6.0"],
            "transporters.min_speed",
            "expected at most speed (5), got 6",
            id="min-speed-above-speed",
        ),
        pytest.param(
            ["transporters.handover_time=6", "messaging.patience=5"],
            "messaging.patience",
            "expected more than transporters.handover_time + messaging.timeout (6 + 0.5), got 5",
            id="patience-shorter-than-a-hand-over",
        ),
        pytest.param(
            ["strategy.name=fastest"],
            "strategy.name",
            "expected one of time, random, solo, time_gain, sink_first or 'package.module:Class',"
            " got 'fastest'",
            id="unknown-strategy",
        ),
        pytest.param(
            ["strategy.name=no_such_package.strategies:Best"],
            "strategy.name",
            "cannot import 'no_such_package.strategies'",
            id="strategy-module-missing",
        ),
        pytest.param(
            ["strategy.name=apps.fire_brigade.strategies:NoSuchStrategy"],
            "strategy.name",
            "is not a subclass of apps.fire_brigade.Strategy",
            id="strategy-class-missing",
        ),
        pytest.param(
            ["strategy.name=apps.fire_brigade.goal:Goal"],
            "strategy.name",
            "'apps.fire_brigade.goal:Goal' is not a subclass of apps.fire_brigade.Strategy",
            id="strategy-not-a-strategy",
        ),
        pytest.param(
            ["strategy.name=math:pi"],
            "strategy.name",
            "is not a subclass",
            id="strategy-not-a-class",
        ),
        pytest.param(
            ["strategy.name=apps.fire_brigade.strategies:"],
            "strategy.name",
            "'package.module:Class'",
            id="strategy-path-without-class",
        ),
        pytest.param(
            ["stations.generators=[]"],
            "stations.generators",
            "expected at least one position, got none",
            id="no-generators",
        ),
        pytest.param(
            ["stations.sinks=[]"],
            "stations.sinks",
            "expected at least one position, got none",
            id="no-sinks",
        ),
        pytest.param(
            ["stations.generators=[[4.0, 9.0]]"],
            "stations",
            "two stations stand at the same position",
            id="generator-on-a-sink",
        ),
        pytest.param(
            ["stations.sinks=[[4.0, 9.0], [4.0, 9.0]]"],
            "stations",
            "two stations stand at the same position",
            id="two-sinks-at-one-spot",
        ),
        pytest.param(
            ["stations.generators=[[4, 0], [4.0, 0.0]]"],
            "stations",
            "two stations stand at the same position",
            id="same-spot-int-and-float",
        ),
    ],
)
def test_a_mistake_is_reported_against_its_key(overrides: list[str], key: str, says: str) -> None:
    [(found, message)] = problems_of(overrides)
    assert found == key
    assert says in message


@pytest.mark.parametrize("name", SHIPPED)
def test_every_shipped_scenario_is_checked_the_same_way(name: str) -> None:
    keys = keys_of(["transporters.min_speed=100.0", "strategy.name=nope"], name)
    assert keys == ["transporters.min_speed", "strategy.name"]


def test_every_problem_is_reported_at_once() -> None:
    keys = keys_of(
        [
            "stations.generators=[[11.0, 0.0], [8.0, 0.0]]",
            "stations.sinks=[[4.0, 9.0], [-8.0, 9.0]]",
            "transporters.spawn_min=[9.0, 1.0]",
            "transporters.spawn_max=[3.0, 70.0]",
            "transporters.min_speed=5.5",
            "strategy.name=apps.fire_brigade.task:Task",
        ]
    )
    assert keys == [
        "stations.generators[0]",
        "stations.sinks[1]",
        "transporters.spawn_max",  # outside the world
        "transporters.spawn_max",  # and below spawn_min
        "transporters.min_speed",
        "strategy.name",
    ]


def test_a_smaller_world_moves_robots_outside_it() -> None:
    assert keys_of(["world.width=6"]) == [
        "stations.generators[1]",
        "stations.sinks[1]",
        "transporters.spawn_max",
    ]


def test_per_key_bounds_come_from_the_config_sections() -> None:
    # Single-key bounds are the loader's job (setting(gt=...)); check() adds the cross-key ones.
    keys = keys_of(["transporters.speed=0", "strategy.search_growth=0.5"])
    assert sorted(keys) == ["strategy.search_growth", "transporters.speed"]


def test_check_works_on_a_config_built_in_python() -> None:
    app = FireBrigade()
    app.check(FireBrigadeConfig(), WORLD)
    config = FireBrigadeConfig(
        stations=Stations(generators=((1.0, 1.0),), sinks=((1.0, 1.0), (20.0, 1.0))),
        transporters=Transporters(speed=2.0, min_speed=3.0),
        strategy=StrategyConfig(name="tests.fire_brigade.test_config:NotAStrategy"),
    )
    with pytest.raises(ScenarioError) as caught:
        app.check(config, WORLD)
    assert caught.value.file is None
    assert [key for key, _ in caught.value.problems] == [
        "stations.sinks[1]",
        "stations",
        "transporters.min_speed",
        "strategy.name",
    ]
    assert "stations.sinks[1]: expected a position inside the world" in str(caught.value)


class NotAStrategy:
    """Named by a scenario as its strategy: refused, it is no Strategy subclass."""


class MyStrategy(TimeStrategy):
    """A user's own strategy, named by its import path."""


def test_a_user_strategy_is_named_by_its_import_path() -> None:
    scenario = load_scenario(BASE, ["strategy.name=tests.fire_brigade.test_config:MyStrategy"])
    assert scenario.config.strategy.name == "tests.fire_brigade.test_config:MyStrategy"


# -- build() -----------------------------------------------------------------------------


def setup_for(
    config: FireBrigadeConfig, seed: int = 1, world: tuple[float, float] = WORLD
) -> SimulationSetup:
    """What the scenario runner would hand ``build``, with a seeded generator."""
    return SimulationSetup(
        config, world, Environment(), VirtualClock(), MemoryTransport(), np.random.default_rng(seed)
    )


def build(config: FireBrigadeConfig, seed: int = 1) -> tuple[Mission, SimulationSetup]:
    setup = setup_for(config, seed)
    return FireBrigade().build(setup), setup


def test_build_numbers_generators_then_sinks_then_transporters() -> None:
    config = load_scenario(BASE).config
    mission, setup = build(config)
    ids = [robot.robot_id for robot in mission.robots]
    assert ids == list(range(1, 21))
    assert mission.groups == {
        "Generator": [1, 2],
        "Sink": [3, 4],
        "Transporter": list(range(5, 21)),
    }
    assert setup.environment.robot_ids == tuple(ids)
    assert mission.target == 20
    assert mission.extra is not None
    assert mission.extra() == {"strategy": "time_gain"}
    assert list(mission.measures) == ["line_share"]
    assert tuple(mission.snapshot_exchanges) == (35, 95, 125, 200)  # thesis Fig. 34


def test_build_places_the_stations_where_the_config_says() -> None:
    config = load_scenario(BASE).config
    _, setup = build(config)
    env = setup.environment
    stations = [*config.stations.generators, *config.stations.sinks]
    for robot_id, (x, y) in enumerate(stations, start=1):
        pose = env.pose_at(robot_id, 0.0)
        assert (pose.x, pose.y) == (x, y)
        assert not env.is_mobile(robot_id)
    assert all(env.is_mobile(robot_id) for robot_id in range(5, 21))


def test_build_gives_each_robot_its_kind_and_the_others_as_peers() -> None:
    mission, _ = build(load_scenario(BASE).config)
    kinds = {robot.robot_id: robot.layers[0].params.kind for robot in mission.robots}  # type: ignore[attr-defined]
    assert kinds == {1: Kind.GENERATOR, 2: Kind.GENERATOR, 3: Kind.SINK, 4: Kind.SINK} | {
        robot_id: Kind.TRANSPORTER for robot_id in range(5, 21)
    }
    for robot in mission.robots:
        params = robot.layers[0].params  # type: ignore[attr-defined]
        assert all(layer.params is params for layer in robot.layers)  # type: ignore[attr-defined]
        assert params.peers == tuple(r for r in range(1, 21) if r != robot.robot_id)
        assert params.world == WORLD
        assert (params.speed, params.deceleration, params.min_speed) == (5.0, 1.0, 1.0)
        assert params.range == 5.0


@pytest.mark.parametrize(
    ("name", "cls"),
    [
        pytest.param("time", TimeStrategy, id="time"),
        pytest.param("random", RandomStrategy, id="random"),
        pytest.param("solo", SoloStrategy, id="solo"),
        pytest.param("tests.fire_brigade.test_config:MyStrategy", MyStrategy, id="user-class"),
    ],
)
def test_build_stacks_the_five_layers_with_the_named_strategy(
    name: str, cls: type[Strategy]
) -> None:
    config = load_scenario(BASE, [f"strategy.name={name}"]).config
    mission, _ = build(config)
    for robot in mission.robots:
        assert [type(layer) for layer in robot.layers] == [Goal, cls, GroupActivity, Task, Action]


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 99])
def test_build_spawns_transporters_inside_the_spawn_area(seed: int) -> None:
    config = load_scenario(BASE, ["transporters.count=50"]).config
    mission, setup = build(config, seed)
    (x0, y0), (x1, y1) = config.transporters.spawn_min, config.transporters.spawn_max
    transporters = mission.groups["Transporter"]
    assert len(transporters) == 50
    for robot_id in transporters:
        pose = setup.environment.pose_at(robot_id, 0.0)
        assert x0 <= pose.x <= x1
        assert y0 <= pose.y <= y1
        assert -math.pi <= pose.heading <= math.pi


def test_a_spawn_area_of_one_point_puts_every_transporter_there() -> None:
    config = load_scenario(
        BASE, ["transporters.spawn_min=[2.5, 3.5]", "transporters.spawn_max=[2.5, 3.5]"]
    ).config
    mission, setup = build(config)
    for robot_id in mission.groups["Transporter"]:
        pose = setup.environment.pose_at(robot_id, 0.0)
        assert (pose.x, pose.y) == (2.5, 3.5)


def poses(config: FireBrigadeConfig, seed: int) -> list[tuple[float, float, float]]:
    _, setup = build(config, seed)
    env = setup.environment
    return [(pose.x, pose.y, pose.heading) for pose in (env.pose_at(r, 0.0) for r in env.robot_ids)]


def seeds(config: FireBrigadeConfig, seed: int) -> list[int]:
    mission, _ = build(config, seed)
    return [robot.layers[0].params.seed for robot in mission.robots]  # type: ignore[attr-defined]


def test_build_is_reproducible_by_seed() -> None:
    config = load_scenario(BASE).config
    assert poses(config, 7) == poses(config, 7)
    assert seeds(config, 7) == seeds(config, 7)
    assert poses(config, 7) != poses(config, 8)
    assert seeds(config, 7) != seeds(config, 8)
    assert len(set(seeds(config, 7))) == 20  # each robot its own random stream


def test_build_follows_the_config_not_the_defaults() -> None:
    config = dataclasses.replace(
        FireBrigadeConfig(),
        stations=Stations(generators=((1.0, 2.0),), sinks=((9.0, 8.0),)),
        transporters=Transporters(count=3, speed=2.0, min_speed=0.5, handover_time=0.25),
        strategy=StrategyConfig(name="solo", range=3.0, search_step=0.5),
    )
    mission, setup = build(config)
    assert mission.groups == {"Generator": [1], "Sink": [2], "Transporter": [3, 4, 5]}
    assert mission.target == 20
    transporter = mission.robots[2]
    params = transporter.layers[0].params  # type: ignore[attr-defined]
    assert (params.speed, params.min_speed, params.handover_time) == (2.0, 0.5, 0.25)
    assert (params.range, params.search_step) == (3.0, 0.5)
    assert isinstance(transporter.layers[1], SoloStrategy)
    assert setup.environment.pose_at(1, 0.0).y == 2.0


def test_the_messages_are_the_apps_own() -> None:
    names = {cls.__name__ for cls in MESSAGES}
    assert names == {
        "Abandoned",
        "BucketMade",
        "Carry",
        "CompletionStatus",
        "Exchanged",
        "Give",
        "Handover",
        "HoldOut",
        "MakeBucket",
        "Meet",
        "MeetAt",
        "Meeting",
        "MeetingPoint",
        "Move",
        "MoveBucket",
        "Moved",
        "PartnerAnswer",
        "Partnered",
        "RequestInfo",
        "RequestPartner",
        "RequestRobotsInRange",
        "RobotInfo",
        "RobotsInRange",
        "Rotate",
        "Take",
        "Where",
        "Withdraw",
    }


@pytest.mark.parametrize(
    ("overrides", "expected"),
    [
        pytest.param([], {"stations": 4, "transporters.count": 16}, id="thesis"),
        pytest.param(
            ["stations.repeat=3", "stations.repeat_offset=[0.5, 0.0]", "transporters.count=5"],
            {"stations.repeat": 12, "transporters.count": 5},
            id="repeated",
        ),
    ],
)
def test_robots_counts_what_build_makes_without_building(
    overrides: list[str], expected: dict[str, int]
) -> None:
    config = load_scenario(BASE, overrides).config
    assert FireBrigade().robots(config) == expected
    mission, _ = build(config)
    assert len(mission.robots) == sum(expected.values())
