"""One episode of a policy in an environment, summed up: what the baselines and training share."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from gymnasium.spaces import Discrete

from cas_async.rl import ParallelSwarmEnv
from cas_async.scenario import RunStatus

__all__ = ["Policy", "Rollout", "random_policy", "rollout"]

O = TypeVar("O")  # noqa: E741 - the observation type
Policy = Callable[[Mapping[str, O]], dict[str, np.int64]]
"""Actions for every live agent, from their observations."""


@dataclass(frozen=True)
class Rollout:
    """What one episode came to.

    Attributes:
        seed: the episode's seed.
        steps: steps taken.
        mean_return: the sum of each agent's rewards, averaged over the agents.
        status: how the run ended (completed, timed_out).
        makespan: the instant the objective was complete, ``None`` if it was not.
    """

    seed: int
    steps: int
    mean_return: float
    status: RunStatus
    makespan: float | None


def rollout(env: ParallelSwarmEnv[Any, O, np.int64], policy: Policy[O], seed: int) -> Rollout:
    """Runs one episode of ``policy`` from ``env.reset(seed=seed)`` to its end."""
    observations, _ = env.reset(seed=seed)
    returns = dict.fromkeys(env.agents, 0.0)
    steps = 0
    while env.agents:
        observations, rewards, _, _, _ = env.step(policy(observations))
        steps += 1
        for agent, reward in rewards.items():
            returns[agent] += reward
    result = env.run.result  # complete: the episode ended
    return Rollout(
        seed, steps, float(np.mean(list(returns.values()))), result.status, result.makespan
    )


def random_policy(actions: Discrete, seed: int) -> Policy[Any]:
    """Uniformly random actions among ``actions``, seeded."""
    rng = np.random.default_rng(seed)
    n = int(actions.n)

    def policy(observations: Mapping[str, Any]) -> dict[str, np.int64]:
        return {agent: np.int64(rng.integers(n)) for agent in observations}

    return policy
