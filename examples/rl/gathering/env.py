"""The gathering as a PettingZoo environment: what a robot sees, earns and does each step.

Each step (``DT`` = 0.5 simulated seconds) every robot holds one of nine actions:
drive a leg of ``speed * DT`` in one of eight headings (0 is east, then every 45
degrees counter-clockwise), or stay (8). A leg ends just before the step does, so
every robot stands still when the step's observation is taken.

* Observation (4 floats in [-1, 1]): the unit vector from the robot to the meeting
  point it knows (the centroid of the starts it heard, its own included: before the
  robots start, its own start), the distance to it over the world's diagonal, and 1
  when it stands within the gathering radius (else 0).
* Reward: the distance gained toward the meeting point during the step, in legs
  (1 for a full leg straight at it), less 0.1 per step (waiting costs), plus 5 for
  every robot when the last one gathers (the episode terminates): the sooner the
  whole swarm gathers, the more each robot earns.

The episode terminates when every robot stands within the radius at once (the
gathering's objective); it is truncated at ``run.max_time`` (40 s: 80 steps).
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
from examples.gathering.plan import Point

from .layer import LearnedPlan

__all__ = [
    "ACTIONS",
    "DT",
    "OBSERVATIONS",
    "SCENARIO",
    "STAY",
    "Gathering",
    "GatheringEnv",
    "make_env",
]

SCENARIO: Final = Path(__file__).with_name("gathering.toml")
DT: Final = 0.5
"""Simulated seconds per step."""
HEADINGS: Final = 8
STAY: Final = HEADINGS
"""The action that keeps a robot where it stands."""
ACTIONS: Final = Discrete(HEADINGS + 1)
OBSERVATIONS: Final = Box(-1.0, 1.0, shape=(4,), dtype=np.float32)
STEP_COST: Final = 0.1
COMPLETION_BONUS: Final = 5.0
_JUST_UNDER: Final = 1 - 1e-6
"""A leg lasts this fraction of a step: it is over before the step ends."""

Observation: TypeAlias = npt.NDArray[np.float32]
GatheringEnv: TypeAlias = ParallelSwarmEnv[LearnedPlan, Observation, np.int64]


@dataclass(frozen=True)
class Gathering:
    """The task's rules, from the scenario: what a robot sees, earns and does.

    Attributes:
        leg: how far a robot drives in one step, metres.
        radius: how close to the meeting point a robot must stand to have gathered.
        world: ``(width, height)``: legs stop at its edges.
    """

    leg: float
    radius: float
    world: tuple[float, float]

    def observe(self, layer: LearnedPlan) -> Observation:
        """Heading to the meeting point, how far it is, whether the robot is there."""
        meeting = layer.meeting
        dx, dy = meeting[0] - layer.here[0], meeting[1] - layer.here[1]
        gap = math.hypot(dx, dy)
        ux, uy = (dx / gap, dy / gap) if gap > 0 else (0.0, 0.0)
        return np.array(
            [ux, uy, min(gap / math.hypot(*self.world), 1.0), float(gap <= self.radius)],
            dtype=np.float32,
        )

    def reward(self, layer: LearnedPlan, outcome: StepOutcome) -> float:
        """Distance gained in legs, less 0.1 a step, plus 5 at completion."""
        meeting = layer.meeting
        pose = outcome.environment.pose_at(layer.robot_id, outcome.time)
        before = math.dist(layer.step_start, meeting)
        after = math.dist((pose.x, pose.y), meeting)
        bonus = COMPLETION_BONUS if outcome.complete else 0.0
        return (before - after) / self.leg - STEP_COST + bonus

    def act(self, layer: LearnedPlan, action: np.int64, here: Point) -> Point:
        """Where this step's leg ends: one leg along the heading, inside the world; or here."""
        k = int(action)
        if k == STAY:
            return here
        angle = k * 2 * math.pi / HEADINGS
        x = here[0] + self.leg * math.cos(angle)
        y = here[1] + self.leg * math.sin(angle)
        width, height = self.world
        return (min(max(x, 0.0), width), min(max(y, 0.0), height))


def make_env(
    scenario: str | Path = SCENARIO,
    *,
    overrides: Sequence[str] = (),
    render_mode: str | None = None,
    dt: float = DT,
) -> GatheringEnv:
    """The gathering environment: ``scenario`` (with ``overrides``), its Plan layer learned."""
    loaded = load_scenario(scenario, overrides)
    fleet, meeting = loaded.config.robots, loaded.config.gathering
    rules = Gathering(
        leg=fleet.speed * dt * _JUST_UNDER,
        radius=meeting.radius,
        world=(loaded.world.width, loaded.world.height),
    )
    return ParallelSwarmEnv(
        loaded,
        level="plan",
        layer=LearnedPlan,
        observe=rules.observe,
        reward=rules.reward,
        act=rules.act,
        observation_space=OBSERVATIONS,
        action_space=ACTIONS,
        dt=dt,
        render_mode=render_mode,
    )
