"""The Fire Brigade's ``[messaging]`` section: timeouts, retries and patience, end to end.

The section is validated by the scenario loader, reaches every layer's ``Params``
through ``FireBrigade.build``, and shapes how the layers live with a lossy network:
a Strategy layer asks a silent robot ``retries`` more times, ``timeout`` apart,
before asking the next one.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from apps.fire_brigade import TimeStrategy
from apps.fire_brigade.app import FireBrigade
from apps.fire_brigade.base import Params
from apps.fire_brigade.config import FireBrigadeConfig, Messaging
from apps.fire_brigade.messages import Kind
from cas_async import MemoryTransport, Message, MsgType, RobotId, VirtualClock
from cas_async.scenario import Mission, ScenarioError, SimulationSetup, load_scenario
from cas_async.sim import Environment
from tests.fire_brigade.helpers import SCENARIOS, run_checked

BASE = SCENARIOS / "thesis_5_8_1.toml"

TINY = [
    "stations.generators=[[1.0, 1.0]]",
    "stations.sinks=[[1.0, 9.0]]",
    "transporters.spawn_min=[2.0, 1.0]",
    "transporters.spawn_max=[2.0, 1.0]",
    "mission.buckets=1",
]
"""One Generator (robot 1), one Sink (robot 2), transporters all at one spot near the generator."""


def build(overrides: Sequence[str] = (), scenario: Path = BASE) -> Mission:
    """The swarm ``FireBrigade.build`` makes for ``scenario`` with ``overrides``."""
    config = load_scenario(scenario, overrides).config
    assert isinstance(config, FireBrigadeConfig)
    setup = SimulationSetup(
        config,
        (10.0, 10.0),
        Environment(),
        VirtualClock(),
        MemoryTransport(),
        np.random.default_rng(1),
    )
    return FireBrigade().build(setup)


def every_params(mission: Mission) -> Iterator[Params]:
    """The Params of every layer of every robot."""
    for robot in mission.robots:
        for layer in robot.layers:
            params = layer.params  # type: ignore[attr-defined]
            assert isinstance(params, Params)
            yield params


def messaging_of(params: Params) -> tuple[float, int, float]:
    return params.timeout, params.retries, params.patience


# -- the section ------------------------------------------------------------------------


def test_the_defaults_are_those_documented() -> None:
    assert Messaging() == Messaging(timeout=0.5, retries=6, patience=30.0)
    assert FireBrigadeConfig().messaging == Messaging()


def test_a_scenario_without_the_section_gets_the_defaults_in_every_layer() -> None:
    assert load_scenario(BASE).config.messaging == Messaging()
    found = {messaging_of(params) for params in every_params(build())}
    assert found == {(0.5, 6, 30.0)}


def test_params_defaults_agree_with_the_section_defaults() -> None:
    params = next(every_params(build()))
    bare = Params(
        kind=params.kind,
        peers=params.peers,
        world=params.world,
        speed=params.speed,
        deceleration=params.deceleration,
        min_speed=params.min_speed,
        handover_time=params.handover_time,
        range=params.range,
        search_step=params.search_step,
        retry_interval=params.retry_interval,
        search_growth=params.search_growth,
        seed=params.seed,
    )
    defaults = Messaging()
    assert messaging_of(bare) == (defaults.timeout, defaults.retries, defaults.patience)


@pytest.mark.parametrize(
    ("overrides", "expected"),
    [
        pytest.param(["messaging.timeout=0.2"], (0.2, 6, 30.0), id="timeout"),
        pytest.param(["messaging.retries=0"], (0.5, 0, 30.0), id="no-retries"),
        pytest.param(["messaging.retries=11"], (0.5, 11, 30.0), id="retries"),
        pytest.param(["messaging.patience=2.5"], (0.5, 6, 2.5), id="patience"),
        pytest.param(
            ["messaging.timeout=0.25", "messaging.retries=3", "messaging.patience=7"],
            (0.25, 3, 7.0),
            id="all-three",
        ),
    ],
)
def test_overrides_reach_every_layer_of_every_robot(
    overrides: list[str], expected: tuple[float, int, float]
) -> None:
    mission = build([*TINY, "transporters.count=2", *overrides])
    assert len(mission.robots) == 4
    assert {messaging_of(params) for params in every_params(mission)} == {expected}
    kinds = {params.kind for params in every_params(mission)}
    assert kinds == {Kind.GENERATOR, Kind.SINK, Kind.TRANSPORTER}


def test_the_section_is_read_from_the_scenario_file(tmp_path: Path) -> None:
    scenario = tmp_path / "patient.toml"
    text = BASE.read_text(encoding="utf-8")
    scenario.write_text(
        text + "\n[messaging]\ntimeout = 0.125\nretries = 2\npatience = 4.0\n", encoding="utf-8"
    )
    assert load_scenario(scenario).config.messaging == Messaging(0.125, 2, 4.0)
    found = {messaging_of(params) for params in every_params(build(scenario=scenario))}
    assert found == {(0.125, 2, 4.0)}
    # An override beats the file.
    mission = build(["messaging.retries=5"], scenario=scenario)
    assert {messaging_of(params) for params in every_params(mission)} == {(0.125, 5, 4.0)}


@pytest.mark.parametrize(
    ("override", "key", "says"),
    [
        pytest.param("messaging.timeout=0", "messaging.timeout", "> 0, got 0", id="zero-timeout"),
        pytest.param(
            "messaging.timeout=-0.5", "messaging.timeout", "> 0, got -0.5", id="negative-timeout"
        ),
        pytest.param("messaging.timeout=nan", "messaging.timeout", "not finite", id="nan-timeout"),
        pytest.param(
            'messaging.timeout="fast"', "messaging.timeout", "a string", id="text-timeout"
        ),
        pytest.param(
            "messaging.retries=-1", "messaging.retries", ">= 0, got -1", id="negative-retries"
        ),
        pytest.param(
            "messaging.retries=1.5", "messaging.retries", "an integer", id="fractional-retries"
        ),
        pytest.param(
            "messaging.patience=0", "messaging.patience", "> 0, got 0", id="zero-patience"
        ),
        pytest.param(
            "messaging.patience=-3", "messaging.patience", "> 0, got -3", id="negative-patience"
        ),
    ],
)
def test_an_invalid_value_names_its_key(override: str, key: str, says: str) -> None:
    with pytest.raises(ScenarioError) as caught:
        load_scenario(BASE, [override])
    [(found, message)] = caught.value.problems
    assert found == key
    assert says in message
    assert f"{key}: " in str(caught.value)


def test_an_unknown_key_is_named_with_its_section() -> None:
    with pytest.raises(ScenarioError) as caught:
        load_scenario(BASE, ["messaging.timeuot=0.2"])
    [(found, message)] = caught.value.problems
    # The loader reports unknown keys against their table, naming the key and the valid ones.
    assert found == "messaging"
    assert "unknown key 'timeuot'" in message
    assert "patience, retries, timeout" in message


def test_every_invalid_value_is_reported_at_once() -> None:
    with pytest.raises(ScenarioError) as caught:
        load_scenario(
            BASE, ["messaging.timeout=0", "messaging.retries=-2", "messaging.patience=-1"]
        )
    keys = sorted(key for key, _ in caught.value.problems)
    assert keys == ["messaging.patience", "messaging.retries", "messaging.timeout"]


@pytest.mark.parametrize(
    ("timeout", "retries"),
    [(0.5, 6), (0.2, 0), (0.25, 3), (1.0, 1), (3.0, 9)],
    ids=["defaults", "no-retries", "quarter", "one-retry", "slow"],
)
def test_give_up_after_is_every_attempt_waited_out(timeout: float, retries: int) -> None:
    mission = build([f"messaging.timeout={timeout}", f"messaging.retries={retries}"])
    for params in every_params(mission):
        assert params.give_up_after == (retries + 1) * timeout


# -- behaviour on a lossy network -----------------------------------------------------------


def test_a_run_that_loses_every_datagram_times_out() -> None:
    timeout, max_time = 0.2, 5.0
    result, _, _ = run_checked(
        BASE,
        [
            *TINY,
            "transporters.count=1",
            "faults.loss=1.0",
            f"run.max_time={max_time}",
            f"messaging.timeout={timeout}",
            "messaging.retries=2",
        ],
    )
    assert result.status.value == "timed_out", result.error
    assert result.sim_time == max_time
    assert result.delivered == result.exchanges == 0
    assert result.faults is not None
    assert result.faults["lost"] == result.faults["sent"] > 0
    # Nobody ever heard of a Sink, so the Generator keeps asking who is one, every
    # timeout, and never gets as far as looking for a partner.
    rounds = int(max_time / timeout)
    assert set(result.messages_external) == {"RequestInfo"}
    assert result.messages_external["RequestInfo"] >= 2 * rounds  # two peers per round
    assert result.messages_external["RequestInfo"] == result.faults["sent"]


Send = tuple[float, RobotId, RobotId, int, str]
"""A RequestPartner leaving a Strategy layer: (time, from, to, msg_id, "send" or "resend")."""


class SilentTransporters(TimeStrategy):
    """Transporters never answer a partnership request; every Strategy logs what it asks.

    To the asker this is a partner whose answers are all lost on the wire; the other
    layers still talk, so the Generator learns where the Sink is and gets that far.
    """

    sent: ClassVar[list[Send]] = []

    def send(self, robot_id: RobotId, msg: Message) -> None:
        super().send(robot_id, msg)
        self.sent.append((self.clock.now(), self.robot_id, robot_id, msg.msg_id, "send"))

    def resend(self, robot_id: RobotId, msg: Message) -> None:
        super().resend(robot_id, msg)
        self.sent.append((self.clock.now(), self.robot_id, robot_id, msg.msg_id, "resend"))

    async def handle_msg(self, msg: Message) -> None:
        if self.kind is Kind.TRANSPORTER and msg.msg_type == MsgType.NEGOTIATION:
            return
        await super().handle_msg(msg)


@pytest.fixture
def asked() -> Iterator[list[Send]]:
    SilentTransporters.sent = []
    yield SilentTransporters.sent
    SilentTransporters.sent = []


@pytest.mark.parametrize("retries", [0, 2], ids=["no-retries", "two-retries"])
def test_a_silent_robot_is_asked_retries_more_times_before_the_next_one(
    asked: list[Send], retries: int
) -> None:
    timeout = 0.25
    result, _, _ = run_checked(
        BASE,
        [
            *TINY,
            "transporters.count=2",  # robots 3 and 4, both silent
            "strategy.name=tests.fire_brigade.test_messaging:SilentTransporters",
            f"messaging.timeout={timeout}",
            f"messaging.retries={retries}",
            "run.max_time=3.0",
        ],
    )
    assert result.status.value == "timed_out", result.error
    assert result.messages_external["RequestPartner"] == len(asked)
    assert {(sender, to) for _, sender, to, _, _ in asked} <= {(1, 3), (1, 4)}
    give_up_after = (retries + 1) * timeout
    first, second = asked[: retries + 1], asked[retries + 1 : 2 * (retries + 1)]
    for attempts in (first, second):
        # One request, sent once and resent ``retries`` times, to one robot, timeout apart.
        assert [kind for *_, kind in attempts] == ["send"] + ["resend"] * retries
        assert len({(to, msg_id) for _, _, to, msg_id, _ in attempts}) == 1
        start = attempts[0][0]
        assert [t for t, *_ in attempts] == pytest.approx(
            [start + k * timeout for k in range(retries + 1)]
        )
    # Then the other robot, once the first counted as silent.
    assert first[0][2] != second[0][2]
    assert first[0][3] != second[0][3]
    assert second[0][0] == pytest.approx(first[0][0] + give_up_after)
