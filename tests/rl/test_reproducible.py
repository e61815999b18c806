"""On virtual time a seed fixes an episode: its observations, rewards and makespan.

* The same seed gives identical observations and rewards, step for step, over 200
  steps: in two envs, and in one env after other episodes.
* Holding action 0 in the Fire Brigade is the time strategy: its makespan is the
  built-in strategy's to the last bit (and so are its deliveries), whatever ``dt``
  (a decision is taken at its instant, never moved to a step's end).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

pytest.importorskip("pettingzoo")

from cas_async.testing import run_scenario_file
from examples.rl.fire_brigade.env import SCENARIO as FIRE_BRIGADE
from examples.rl.fire_brigade.env import make_env as fire_brigade
from examples.rl.gathering.env import make_env as gathering

STEPS = 200

Record = list[tuple[str, list[float], dict[str, float], dict[str, bool]]]


def record(env: Any, seeds: list[int], steps: int, policy_seed: int) -> Record:
    """Observations, rewards and terminations of ``steps`` steps of a seeded random policy.

    Episodes follow each other with ``seeds``, in order, until ``steps`` were taken.
    """
    rng = np.random.default_rng(policy_seed)
    out: Record = []
    seeds = list(seeds)
    observations, _ = env.reset(seed=seeds.pop(0))
    for _ in range(steps):
        if not env.agents:
            observations, _ = env.reset(seed=seeds.pop(0))
        actions = {agent: np.int64(rng.integers(env.action_space(agent).n)) for agent in env.agents}
        observations, rewards, terminations, _, _ = env.step(actions)
        for agent in sorted(observations):
            out.append((agent, observations[agent].tolist(), rewards, terminations))
    return out


@pytest.mark.parametrize(
    ("factory", "overrides"),
    [
        (gathering, ["run.max_time=120"]),
        pytest.param(fire_brigade, [], marks=pytest.mark.slow),
    ],
    ids=["gathering", "fire_brigade"],
)
def test_the_same_seed_gives_the_same_observations_and_rewards_over_200_steps(
    factory: Callable[..., Any], overrides: list[str], make: Callable[..., Any]
) -> None:
    first = record(make(factory, overrides=overrides), [3, 4, 5, 6, 7, 8], STEPS, policy_seed=9)
    second = record(make(factory, overrides=overrides), [3, 4, 5, 6, 7, 8], STEPS, policy_seed=9)
    assert len(first) >= STEPS
    assert first == second
    other = record(make(factory, overrides=overrides), [4], 20, policy_seed=9)
    assert other != first[: len(other)]  # the seed matters: the comparison above could fail


def test_an_episode_does_not_depend_on_the_episodes_before_it(make: Callable[..., Any]) -> None:
    env = make(gathering)
    alone = record(make(gathering), [11], 40, policy_seed=1)
    record(env, [5, 6], 90, policy_seed=2)  # other episodes first, one left in the middle
    assert record(env, [11], 40, policy_seed=1) == alone


@pytest.mark.parametrize(
    ("seed", "dt"),
    [
        (1, 0.5),
        pytest.param(2, 0.1, marks=pytest.mark.slow),
        pytest.param(3, 3.7, marks=pytest.mark.slow),
    ],
)
@pytest.mark.slow  # a few seconds: the fast suite stays under 2 minutes
def test_holding_the_first_ranked_partner_is_the_time_strategy_to_the_last_bit(
    seed: int, dt: float, make: Callable[..., Any]
) -> None:
    builtin = run_scenario_file(FIRE_BRIGADE, f"run.seed={seed}", "strategy.name=time").result
    env = make(fire_brigade, dt=dt)
    env.reset(seed=seed)
    steps = 0
    while env.agents:
        env.step(dict.fromkeys(env.agents, np.int64(0)))
        steps += 1
    learned = env.result
    assert builtin.status == learned.status == "completed"
    assert learned.makespan == builtin.makespan  # exactly: no tolerance
    assert learned.delivery_times == builtin.delivery_times
    assert learned.exchanges == builtin.exchanges
    assert learned.messages_external == builtin.messages_external
    assert steps == int(np.ceil(builtin.makespan / dt))  # the last step ends at the makespan
    assert env.time == builtin.makespan


@pytest.mark.slow  # a few seconds: the fast suite stays under 2 minutes
def test_another_choice_changes_the_run(make: Callable[..., Any]) -> None:
    """The comparison above can fail: asking the second ranked robot first is another run."""
    builtin = run_scenario_file(FIRE_BRIGADE, "run.seed=1", "strategy.name=time").result
    env = make(fire_brigade)
    env.reset(seed=1)
    while env.agents:
        env.step(dict.fromkeys(env.agents, np.int64(1)))
    assert env.result.makespan != builtin.makespan
