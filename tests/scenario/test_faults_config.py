"""The optional ``[faults]`` table: loading, overrides, and a faulty run end to end."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

import cas_async
from cas_async import Faults, Layer, Message, Pose, Robot, message
from cas_async.scenario import (
    DEFAULT_LATENCY,
    FaultsConfig,
    Mission,
    RunResult,
    RunStatus,
    ScenarioError,
    SimulationSetup,
    load_scenario,
    run_scenario,
    setting,
)
from cas_async.scenario.output import summary_table, write_results
from cas_async.sim import Environment
from tests.scenario.fake_app import FakeApp

MINIMAL = """
app = "tests.scenario.fake_app"
[world]
width = 10
height = 10
"""

WITH_FAULTS = (
    MINIMAL
    + """
[faults]
loss = 0.1
duplicate = 0.05
reorder = 0.05
delay = [0.0, 0.2]
seed = 7
"""
)

WriteScenario = Callable[[str], Path]


@pytest.fixture
def write(tmp_path: Path) -> WriteScenario:
    """Factory: ``path = write(toml_text)`` makes a scenario file under tmp_path."""

    def make(text: str) -> Path:
        path = tmp_path / "scenario.toml"
        path.write_text(text, encoding="utf-8")
        return path

    return make


def problems_loading(path: Path, overrides: tuple[str, ...] = ()) -> list[tuple[str, str]]:
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path, overrides)
    assert caught.value.file == str(path)
    return list(caught.value.problems)


# -- loading ---------------------------------------------------------------------------------


def test_a_faults_table_is_loaded(write: WriteScenario) -> None:
    scenario = load_scenario(write(WITH_FAULTS))
    assert scenario.faults == FaultsConfig(
        loss=0.1, duplicate=0.05, reorder=0.05, delay=(0.0, 0.2), seed=7
    )
    assert scenario.faults.as_faults() == Faults(0.1, 0.05, 0.05, (0.0, 0.2))
    assert scenario.data["faults"]["loss"] == 0.1  # recorded with the results


def test_no_faults_table_means_no_faults(write: WriteScenario) -> None:
    scenario = load_scenario(write(MINIMAL))
    assert scenario.faults == FaultsConfig()
    assert scenario.faults.seed is None
    assert not scenario.faults.as_faults().any


@pytest.mark.parametrize(
    ("table", "key", "message"),
    [
        pytest.param(
            "loss = 1.5", "faults.loss", "expected a number >= 0 and <= 1, got 1.5", id="loss>1"
        ),
        pytest.param(
            "duplicate = -0.1",
            "faults.duplicate",
            "expected a number >= 0 and <= 1, got -0.1",
            id="duplicate<0",
        ),
        pytest.param(
            'reorder = "often"',
            "faults.reorder",
            'expected a number >= 0 and <= 1, got "often" (a string)',
            id="reorder-text",
        ),
        pytest.param(
            "delay = [0.3, 0.1]",
            "faults.delay",
            "expected [min, max] with min <= max, got [0.3, 0.1]",
            id="delay-min-above-max",
        ),
        pytest.param(
            "delay = [0.1]",
            "faults.delay",
            "expected an array of 2 numbers >= 0, got [0.1] (1 item)",
            id="delay-one-number",
        ),
        pytest.param(
            "delay = 0.1",
            "faults.delay",
            "expected an array of 2 numbers >= 0, got 0.1 (a float)",
            id="delay-not-an-array",
        ),
        pytest.param(
            "delay = [-1, 1]", "faults.delay[0]", "expected a number >= 0, got -1", id="delay<0"
        ),
        pytest.param("seed = -1", "faults.seed", "expected an integer >= 0, got -1", id="seed"),
        pytest.param(
            "los = 0.1",
            "faults",
            "unknown key 'los' (did you mean 'loss'? expected one of: "
            "delay, duplicate, loss, reorder, seed)",
            id="unknown-key",
        ),
    ],
)
def test_invalid_faults_name_file_and_key(
    write: WriteScenario, table: str, key: str, message: str
) -> None:
    assert problems_loading(write(f"{MINIMAL}[faults]\n{table}\n")) == [(key, message)]


def test_faults_must_be_a_table(write: WriteScenario) -> None:
    path = write('faults = "lots"\n' + MINIMAL)
    assert problems_loading(path) == [("faults", 'expected a table, got "lots" (a string)')]


def test_set_overrides_faults(write: WriteScenario) -> None:
    path = write(MINIMAL)
    scenario = load_scenario(path, ["faults.loss=0.3", "faults.delay=[0, 0.5]"])
    assert scenario.faults == FaultsConfig(loss=0.3, delay=(0.0, 0.5))
    assert problems_loading(path, ("faults.loss=2",)) == [
        ("faults.loss", "expected a number >= 0 and <= 1, got 2")
    ]


@dataclass(frozen=True)
class _FaultsClashConfig:
    faults: int = 0  # the runner's [faults], not the app's


class _FaultsClash(FakeApp):
    config_type = _FaultsClashConfig  # type: ignore[assignment]


faults_clash = _FaultsClash()


def test_an_app_may_not_have_a_faults_key(write: WriteScenario) -> None:
    text = MINIMAL.replace(
        '"tests.scenario.fake_app"', '"tests.scenario.test_faults_config:faults_clash"'
    )
    assert problems_loading(write(text)) == [
        (
            "app",
            '"tests.scenario.test_faults_config:faults_clash": '
            "config_type may not have keys faults",
        )
    ]


# -- a run with faults: two robots, one pinging the other --------------------------------------


@message(name="FaultsTestPing")
class Ping(Message):
    n: int


class Pinger(Layer):
    """Sends a Ping to robot 2 every 0.1 simulated seconds."""

    def __init__(self) -> None:
        self.sent = 0

    async def inner_process(self) -> None:
        self.send(2, Ping(self.sent))
        self.sent += 1
        self.wake_after(0.1)


class Catcher(Layer):
    """Delivers one item per Ping the robot hands it."""

    def __init__(self, environment: Environment) -> None:
        self.environment = environment

    async def handle_msg(self, msg: Message) -> None:
        t = self.clock.now()
        self.environment.retire_item(self.environment.create_item(self.robot_id, t), 2, t)


@dataclass(frozen=True)
class PingConfig:
    pings: int = setting(20, ge=1, doc="pings to receive")


class PingApp:
    name = "Ping"
    item_name = "ping"
    config_type = PingConfig

    def robots(self, config: PingConfig) -> dict[str, int]:
        return {"robots": 2}

    def check(self, config: PingConfig, world: tuple[float, float]) -> None:
        pass

    def build(self, setup: SimulationSetup) -> Mission:
        robots = [
            Robot(
                robot_id,
                [layer],
                transport=setup.transport,
                clock=setup.clock,
                messages=[Ping],
            )
            for robot_id, layer in ((1, Pinger()), (2, Catcher(setup.environment)))
        ]
        for robot in robots:
            setup.environment.add_robot(robot.robot_id, Pose(0.0, 0.0), mobile=False)
        return Mission(robots=robots, target=setup.config.pings, groups={"Robots": [1, 2]})


ping = PingApp()

PING_RUN = """
app = "tests.scenario.test_faults_config:ping"
pings = 40
[run]
seed = 3
virtual = true
max_time = 60
[world]
width = 10
height = 10
"""


def run(path: Path, overrides: tuple[str, ...] = ()) -> RunResult:
    scenario = load_scenario(path, overrides)
    result, _ = cas_async.run(run_scenario(scenario), virtual=True)
    return result


def test_a_run_with_faults_counts_them_in_results_and_summary(
    write: WriteScenario, tmp_path: Path
) -> None:
    path = write(
        PING_RUN + "[faults]\nloss = 0.2\nduplicate = 0.1\nreorder = 0.1\ndelay = [0, 0.3]\n"
    )
    result = run(path)
    assert result.status is RunStatus.COMPLETED
    faults = result.faults
    assert faults is not None
    assert list(faults) == ["sent", "lost", "duplicated", "reordered", "delayed", "lost_at_close"]
    assert faults["sent"] == result.messages_external["Ping"]
    assert all(faults[key] > 0 for key in ("lost", "duplicated", "reordered", "delayed"))
    data = json.loads(write_results(result, tmp_path / "out").read_text(encoding="utf-8"))
    assert data["faults"] == faults
    line = next(line for line in summary_table(result).splitlines() if line.startswith("faults"))
    assert line == (
        f"faults                {faults['sent']:,} sent, {faults['lost']:,} lost, "
        f"{faults['duplicated']:,} duplicated, {faults['reordered']:,} reordered, "
        f"{faults['delayed']:,} delayed, {faults['lost_at_close']:,} lost at close"
    )
    # Seeded by the run's seed (3) unless the table has its own: the same run again.
    again = run(path)
    assert again.faults == faults
    assert again.makespan == result.makespan
    reseeded = run(path, ("faults.seed=4",))
    assert reseeded.faults != faults


def test_a_run_without_faults_has_none(write: WriteScenario) -> None:
    path = write(PING_RUN + "[faults]\nloss = 0.0\n")  # all zero: the transport is not wrapped
    result = run(path)
    assert result.status is RunStatus.COMPLETED
    assert result.faults is None
    assert not any(line.startswith("faults") for line in summary_table(result).splitlines())
    # ping 0 at t=0, ping 39 sent at t=3.9 and received the network's latency later
    assert result.makespan == pytest.approx(3.9 + DEFAULT_LATENCY)


def test_loss_slows_the_run_down(write: WriteScenario) -> None:
    path = write(PING_RUN)
    clean, lossy = run(path), run(path, ("faults.loss=0.5",))
    assert clean.makespan is not None
    assert lossy.makespan is not None
    assert lossy.makespan > clean.makespan
    assert lossy.faults is not None
    assert lossy.faults["lost"] > 0
