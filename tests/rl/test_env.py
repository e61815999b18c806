"""``ParallelSwarmEnv``'s contract: steps of exactly dt, held actions, ends, errors, lifecycle."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

pytest.importorskip("pettingzoo")

from gymnasium.spaces import Box, Discrete

from cas_async import ConfigurationError
from cas_async.rl import EpisodeFailed, ParallelSwarmEnv, PolicyLayer, StepOutcome
from cas_async.scenario import RunStatus, ScenarioError, load_scenario
from cas_async.testing import run_scenario_file
from examples.gathering.plan import Plan
from examples.rl.fire_brigade.env import SCENARIO as FIRE_BRIGADE
from examples.rl.fire_brigade.env import Partners
from examples.rl.fire_brigade.env import make_env as fire_brigade
from examples.rl.fire_brigade.layer import Choice, LearnedStrategy
from examples.rl.gathering.env import ACTIONS, DT, OBSERVATIONS, SCENARIO, STAY, Gathering
from examples.rl.gathering.env import make_env as gathering
from examples.rl.gathering.layer import LearnedPlan


class NotLearned(Plan):
    """A level's class that is no PolicyLayer."""


def rules() -> Gathering:
    return Gathering(leg=DT * (1 - 1e-6), radius=0.5, world=(20.0, 20.0))


def env_with(make: Callable[..., Any], **changes: Any) -> Any:
    """The gathering env built by hand, with ``changes`` to its arguments."""
    arguments: dict[str, Any] = {
        "level": "plan",
        "layer": LearnedPlan,
        "observe": rules().observe,
        "reward": rules().reward,
        "act": rules().act,
        "observation_space": OBSERVATIONS,
        "action_space": ACTIONS,
        "dt": DT,
    }
    arguments.update(changes)
    scenario = arguments.pop("scenario", SCENARIO)
    return make(ParallelSwarmEnv, scenario=scenario, **arguments)


def greedy(observations: dict[str, Any]) -> dict[str, np.int64]:
    """Straight at the meeting point, and stay once there."""
    actions = {}
    for agent, o in observations.items():
        if o[3] > 0.5 or not (o[0] or o[1]):
            actions[agent] = np.int64(STAY)
        else:
            actions[agent] = np.int64(round(math.atan2(o[1], o[0]) / (math.pi / 4)) % 8)
    return actions


# -- steps ----------------------------------------------------------------------------------------


def test_each_step_advances_virtual_time_by_exactly_dt(make: Callable[..., Any]) -> None:
    seen: list[StepOutcome] = []

    def reward(layer: LearnedPlan, outcome: StepOutcome) -> float:
        seen.append(outcome)
        return 0.0

    env = env_with(make, reward=reward, dt=0.3)
    _, infos = env.reset(seed=2)
    assert env.time == 0.0
    assert {info["time"] for info in infos.values()} == {0.0}
    for k in range(1, 11):
        _, _, _, _, infos = env.step(dict.fromkeys(env.agents, np.int64(STAY)))
        assert env.time == k * 0.3
        assert {info["time"] for info in infos.values()} == {k * 0.3}
    assert [o.time for o in seen[::5]] == [k * 0.3 for k in range(1, 11)]
    assert all(o.dt == pytest.approx(0.3) for o in seen)


def test_the_objective_complete_terminates_every_agent_at_its_instant(
    make: Callable[..., Any],
) -> None:
    gained: list[int] = []

    def reward(layer: LearnedPlan, outcome: StepOutcome) -> float:
        gained.append(outcome.gained)
        return rules().reward(layer, outcome)

    env = env_with(make, reward=reward)
    observations, _ = env.reset(seed=1)
    steps = 0
    while env.agents:
        observations, rewards, terminations, truncations, _ = env.step(greedy(observations))
        steps += 1
    assert all(terminations.values())
    assert not any(truncations.values())
    assert set(terminations) == set(env.possible_agents)
    assert env.result.status is RunStatus.COMPLETED
    assert env.time == env.result.makespan  # the last step ended there, not at a multiple of dt
    assert (steps - 1) * DT < env.result.makespan <= steps * DT
    assert sum(gained) // len(env.possible_agents) == env.result.target
    assert all(r > 4.0 for r in rewards.values())  # the completion bonus
    with pytest.raises(RuntimeError, match="the episode is over"):
        env.step({})


def test_max_time_truncates_and_the_last_step_is_cut_there(make: Callable[..., Any]) -> None:
    env = env_with(make, scenario=load_scenario(SCENARIO, ["run.max_time=3.2"]))
    env.reset(seed=1)
    steps = []
    while env.agents:
        _, _, terminations, truncations, infos = env.step(dict.fromkeys(env.agents, np.int64(0)))
        steps.append(infos["robot_1"]["time"])
    assert steps == [k * 0.5 for k in range(1, 7)] + [3.2]
    assert all(truncations.values())
    assert not any(terminations.values())
    assert env.result.status is RunStatus.TIMED_OUT


def test_a_decision_between_steps_takes_the_action_held_then_at_its_own_instant(
    make: Callable[..., Any],
) -> None:
    decided: list[tuple[float, int, int]] = []  # (instant, robot, action)
    partners = Partners(diagonal=math.hypot(10.0, 10.0))

    def act(layer: LearnedStrategy, action: np.int64, choice: Choice) -> list[int]:
        decided.append((layer.clock.now(), layer.robot_id, int(action)))
        return partners.act(layer, action, choice)

    env = make(fire_brigade)
    env = env_with(
        make,
        scenario=FIRE_BRIGADE,
        level="strategy",
        layer=LearnedStrategy,
        observe=partners.observe,
        reward=partners.reward,
        act=act,
        observation_space=env.observation_space("robot_1"),
        action_space=Discrete(5),
        dt=1.0,
    )
    env.reset(seed=1)
    held: dict[int, list[int]] = {}  # step -> the action each robot held, by robot id
    k = 0
    while env.agents and k < 12:
        actions = {agent: np.int64((k + env.robot_id(agent)) % 5) for agent in env.agents}
        held[k] = [int(actions[f"robot_{robot}"]) for robot in range(1, 21)]
        _, _, _, _, infos = env.step(actions)
        assert sum(info["decisions"] for info in infos.values()) == sum(
            1 for t, _, _ in decided if k < t <= k + 1 or (k == 0 and t == 0)
        )
        k += 1
    assert len(decided) > 20
    off_grid = [t for t, _, _ in decided if t != round(t)]
    assert off_grid, "every decision fell on a step's end: none was taken between steps"
    for t, robot, action in decided:
        step = max(0, math.ceil(t) - 1)  # (k, k + 1] is step k's; t = 0 the first step's
        assert action == held[step][robot - 1], (t, robot)


def test_a_layer_acting_every_step_decides_once_a_step(make: Callable[..., Any]) -> None:
    env = env_with(make)
    env.reset(seed=3)
    for _ in range(4):
        _, _, _, _, infos = env.step(dict.fromkeys(env.agents, np.int64(2)))
        assert {info["decisions"] for info in infos.values()} == {1}


# -- errors ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"level": "planner"}, "no level named 'planner'; the stack's levels are plan"),
        ({"level": 2}, "no level 2"),
        ({"layer": NotLearned}, "expected a subclass of cas_async.rl.PolicyLayer"),
        ({"layer": None}, "not a PolicyLayer: pass layer="),
        ({"dt": 0.0}, "dt: expected a positive number"),
        ({"dt": math.inf}, "dt: expected a positive number"),
        ({"action_space": [0, 1]}, "action_space: expected a gymnasium Space"),
        ({"render_mode": "human"}, "render_mode: expected one of"),
    ],
    ids=["level", "index", "not-policy", "no-layer", "dt-zero", "dt-inf", "space", "render"],
)
def test_a_setup_that_cannot_work_is_refused_with_what_is_wrong(
    changes: dict[str, Any], message: str, make: Callable[..., Any]
) -> None:
    with pytest.raises(ConfigurationError, match=message):
        env_with(make, **changes)


def test_a_policy_layer_defined_in_a_function_is_refused(make: Callable[..., Any]) -> None:
    class Local(PolicyLayer, Plan):
        pass

    with pytest.raises(ConfigurationError, match="define it at module level"):
        env_with(make, layer=Local)


def test_the_loader_checks_the_policy_layer_as_any_replacement(make: Callable[..., Any]) -> None:
    class Strayed(LearnedStrategy):  # a Strategy at the Plan's level
        pass

    Strayed.__qualname__ = "LearnedStrategy"  # a path that imports: the loader's check decides
    with pytest.raises(ScenarioError, match=r"does not subclass examples\.gathering\.plan\.Plan"):
        env_with(make, layer=Strayed)


def test_the_layer_a_scenario_names_in_layers_is_used_when_none_is_given(
    make: Callable[..., Any],
) -> None:
    scenario = load_scenario(SCENARIO, ["layers.plan=examples.rl.gathering.layer:LearnedPlan"])
    env = env_with(make, scenario=scenario, layer=None)
    env.reset(seed=1)
    assert isinstance(env.layer("robot_1"), LearnedPlan)


def test_actions_must_be_one_per_live_agent_and_in_the_space(make: Callable[..., Any]) -> None:
    env = env_with(make)
    with pytest.raises(RuntimeError, match=r"call reset\(\) first"):
        env.step({})
    env.reset(seed=1)
    actions = dict.fromkeys(env.agents, np.int64(0))
    with pytest.raises(ValueError, match="no action for robot_3"):
        env.step({a: x for a, x in actions.items() if a != "robot_3"})
    with pytest.raises(ValueError, match="robot_9 is not a live agent"):
        env.step({**actions, "robot_9": np.int64(0)})
    with pytest.raises(ValueError, match=r"the action for robot_1, 9, is not in Discrete\(9\)"):
        env.step({**actions, "robot_1": 9})
    assert env.time == 0.0  # nothing ran
    env.step(actions)
    assert env.time == DT


def test_an_observation_outside_its_space_names_the_agent(make: Callable[..., Any]) -> None:
    env = env_with(make, observation_space=Box(0.0, 1.0, shape=(4,), dtype=np.float32))
    env.reset(seed=1)  # zeros before the start: inside
    with pytest.raises(ValueError, match=r"observation for robot_1 at t = 0\.5 s that is not in"):
        env.step(dict.fromkeys(env.agents, np.int64(4)))  # west: the heading goes negative


def boom(layer: LearnedPlan, action: np.int64, here: Any) -> Any:
    raise ArithmeticError("the policy's act broke")


def test_an_act_that_raises_fails_the_episode_with_the_robot_and_the_error(
    make: Callable[..., Any],
) -> None:
    env = env_with(make, act=boom)
    env.reset(seed=1)
    with pytest.raises(EpisodeFailed, match="the policy's act broke") as failed:
        env.step(dict.fromkeys(env.agents, np.int64(0)))
    assert "robot 1" in str(failed.value)
    assert env.agents == []
    assert env.result.status is RunStatus.FAILED


def test_a_policy_layer_outside_an_env_says_it_needs_one() -> None:
    outcome = run_scenario_file(
        FIRE_BRIGADE, "layers.strategy=examples.rl.fire_brigade.layer:LearnedStrategy"
    )
    assert outcome.result.status is RunStatus.FAILED
    assert "run it in a cas_async.rl.ParallelSwarmEnv" in (outcome.result.error or "")


# -- lifecycle ------------------------------------------------------------------------------------


def test_reset_stops_a_live_episode_and_close_ends_the_env(make: Callable[..., Any]) -> None:
    env = env_with(make)
    env.reset(seed=1)
    env.step(dict.fromkeys(env.agents, np.int64(0)))
    first = env.run
    env.reset(seed=2)
    assert first.result.status is RunStatus.INTERRUPTED  # its robots were stopped
    env.step(dict.fromkeys(env.agents, np.int64(0)))
    second = env.run
    env.close()
    assert second.result.status is RunStatus.INTERRUPTED
    env.close()  # again: nothing to do
    with pytest.raises(RuntimeError, match="this env is closed"):
        env.reset()
    with pytest.raises(RuntimeError, match="this env is closed"):
        env.step({})


def test_resets_without_a_seed_follow_the_last_seed_given(make: Callable[..., Any]) -> None:
    def seeds(env: Any) -> list[int]:
        env.reset(seed=5)
        out = [env.run.result.seed]
        for _ in range(3):
            env.reset()
            out.append(env.run.result.seed)
        return out

    first, second = seeds(env_with(make)), seeds(env_with(make))
    assert first == second
    assert first[0] == 5
    assert len(set(first)) == 4
    fresh = env_with(make)
    fresh.reset()
    assert fresh.run.result.seed == 1  # the scenario's own seed first


def test_the_spaces_are_the_ones_given_and_the_same_object_every_call(
    make: Callable[..., Any],
) -> None:
    env = env_with(make)
    for agent in env.possible_agents:
        assert env.observation_space(agent) is OBSERVATIONS
        assert env.action_space(agent) is ACTIONS
        assert env.observation_spaces[agent] is OBSERVATIONS
        assert env.action_spaces[agent] is ACTIONS
    assert env.possible_agents == [f"robot_{k}" for k in range(1, 6)]
    assert env.robot_id("robot_4") == 4
    with pytest.raises(KeyError, match="robot_7"):
        env.robot_id("robot_7")


def test_render_draws_the_latest_trace_sample(make: Callable[..., Any]) -> None:
    env = gathering(render_mode="rgb_array")
    try:
        env.reset(seed=1)
        before = env.render()
        for _ in range(6):
            env.step(dict.fromkeys(env.agents, np.int64(0)))  # everyone east
        after = env.render()
    finally:
        env.close()
    assert before.shape == after.shape == (500, 700, 3)
    assert before.dtype == np.uint8
    assert len(np.unique(after.reshape(-1, 3), axis=0)) > 10  # drawn, not blank
    assert not np.array_equal(before, after)  # the robots moved (and the title's time)
    plain = env_with(make)
    plain.reset(seed=1)
    with pytest.raises(RuntimeError, match="render_mode='rgb_array'"):
        plain.render()


async def test_the_env_works_where_an_event_loop_already_runs(make: Callable[..., Any]) -> None:
    """A notebook's cell runs inside the kernel's loop: the env runs its own beside it."""
    env = env_with(make)
    observations, _ = env.reset(seed=1)
    while env.agents:
        observations, _, terminations, _, _ = env.step(greedy(observations))
    assert all(terminations.values())
    env.reset(seed=2)
    env.step(dict.fromkeys(env.agents, np.int64(0)))
    env.close()  # a live episode stopped from inside the running loop too
