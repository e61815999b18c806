"""The Fire Brigade as a PettingZoo environment: each robot picks whom to ask for its bucket.

Whenever a robot with a bucket looks for a partner (the Strategy layer's search,
at whatever instant the protocol gets there), it ranks the robots in range as the
time strategy does, soonest estimated delivery first, and takes the action it
holds (``DT`` = 0.5 simulated seconds per step):

* ``k`` < ``SLOTS``: ask the ``k``-th ranked robot first; if it refuses, the others
  in rank order, then carry the bucket a step toward the sink (a Generator, which
  cannot, waits and looks farther): the built-in rule, with the first pick the
  policy's. A ``k`` past the robots in range asks nobody.
* ``SLOTS`` (none): ask nobody: carry the bucket one step yourself (a Generator waits).

Action 0 in every step is the time strategy itself, to the last bit: the test
suite checks that the makespan is the same.

* Observation (27 floats in [-1, 1]): the robot's kind (3, one-hot), whether it
  holds a bucket, the way to its sink over the world's diagonal (2), and from its
  latest search: its time to carry the bucket alone, and the first ``SLOTS``
  ranked robots (present, offset over the search range (2), estimated delivery
  time, whether it is the sink), times over ``TIME_SCALE`` seconds.
* Reward, the same for every robot: buckets delivered during the step, minus 0.1
  per simulated second (so a faster brigade earns more).

The episode terminates when the 20 buckets are delivered; it is truncated at
``run.max_time`` (120 s).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Final, TypeAlias

import numpy as np
import numpy.typing as npt
from gymnasium.spaces import Box, Discrete

from cas_async.rl import ParallelSwarmEnv, StepOutcome
from cas_async.scenario import load_scenario

from .layer import Choice, LearnedStrategy

__all__ = [
    "ACTIONS",
    "DT",
    "NONE",
    "OBSERVATIONS",
    "SCENARIO",
    "SLOTS",
    "FireBrigadeEnv",
    "Partners",
    "make_env",
]

SCENARIO: Final = Path(__file__).with_name("fire_brigade.toml")
DT: Final = 0.5
"""Simulated seconds per step."""
SLOTS: Final = 4
"""Ranked robots the observation shows and an action may pick."""
NONE: Final = SLOTS
"""The action that asks nobody."""
ACTIONS: Final = Discrete(SLOTS + 1)
_OWN: Final = 7
_PER_SLOT: Final = 5
OBSERVATIONS: Final = Box(-1.0, 1.0, shape=(_OWN + SLOTS * _PER_SLOT,), dtype=np.float32)
TIME_SCALE: Final = 20.0
"""Seconds that an estimated time is divided by (then clipped to 1)."""
COST_PER_SECOND: Final = 0.1

Observation: TypeAlias = npt.NDArray[np.float32]
FireBrigadeEnv: TypeAlias = ParallelSwarmEnv[LearnedStrategy, Observation, np.int64]


@dataclass(frozen=True)
class Partners:
    """The task's rules: what a robot sees, earns, and whom its action asks.

    Attributes:
        diagonal: the world's diagonal, metres.
    """

    diagonal: float

    def observe(self, layer: LearnedStrategy) -> Observation:
        """The robot, its bucket and sink, and its latest search's best candidates."""
        out = np.zeros(OBSERVATIONS.shape, dtype=np.float32)
        out[int(layer.kind)] = 1.0
        if layer.bucket >= 0:
            out[3] = 1.0
            out[4] = _clip((layer.sink_at[0] - layer.here[0]) / self.diagonal)
            out[5] = _clip((layer.sink_at[1] - layer.here[1]) / self.diagonal)
        choice = layer.last_choice
        if choice is None:
            return out
        out[6] = _scaled(choice.alone)
        view = choice.view
        at = {candidate.robot: candidate.at for candidate in view.candidates}
        reach = view.params.range
        for slot, (robot, t) in enumerate(zip(choice.ranked[:SLOTS], choice.times, strict=False)):
            base = _OWN + slot * _PER_SLOT
            x, y = at[robot]
            out[base] = 1.0
            out[base + 1] = _clip((x - view.here[0]) / reach)
            out[base + 2] = _clip((y - view.here[1]) / reach)
            out[base + 3] = _scaled(t)
            out[base + 4] = float(robot == view.sink)
        return out

    def reward(self, layer: LearnedStrategy, outcome: StepOutcome) -> float:
        """Buckets delivered in the step, less 0.1 per simulated second."""
        return outcome.gained - COST_PER_SECOND * outcome.dt

    def act(self, layer: LearnedStrategy, action: np.int64, choice: Choice) -> list[int]:
        """The robots to ask: the picked one first, then the rest by rank; or nobody."""
        k = int(action)
        if k >= min(SLOTS, len(choice.ranked)):
            return []
        first = choice.ranked[k]
        return [first, *(robot for robot in choice.ranked if robot != first)]


def _clip(value: float) -> float:
    return min(max(value, -1.0), 1.0)


def _scaled(seconds: float) -> float:
    return 1.0 if not math.isfinite(seconds) else min(seconds / TIME_SCALE, 1.0)


def make_env(
    scenario: str | Path = SCENARIO,
    *,
    overrides: Sequence[str] = (),
    render_mode: str | None = None,
    dt: float = DT,
) -> FireBrigadeEnv:
    """The Fire Brigade environment: ``scenario`` (with ``overrides``), its Strategy learned."""
    loaded = load_scenario(scenario, overrides)
    rules = Partners(diagonal=math.hypot(loaded.world.width, loaded.world.height))
    return ParallelSwarmEnv(
        loaded,
        level="strategy",
        layer=LearnedStrategy,
        observe=rules.observe,
        reward=rules.reward,
        act=rules.act,
        observation_space=OBSERVATIONS,
        action_space=ACTIONS,
        dt=dt,
        render_mode=render_mode,
    )
