"""A scenario as a PettingZoo parallel environment: :class:`ParallelSwarmEnv`.

Agents are the scenario's robots. The policy acts through one level of their
stack: the env puts a :class:`~cas_async.rl.PolicyLayer` subclass there through
the scenario's ``[layers]`` (``layers.<level> = "module:Class"``, checked by the
loader as any replacement is) and every other level runs as the app wrote it.

``reset(seed)`` rebuilds the scenario with that seed (``run.seed``), on virtual
time with the in-memory transport, and returns what ``observe`` sees of each
robot's policy layer; the robots start at the first step, with its actions in
place. ``step(actions)`` gives every robot its action (held until the next step:
see :mod:`._policy`), advances virtual time by exactly ``dt`` and returns
observations, rewards (``reward(layer, outcome)``), terminations (the mission's
objective is complete, or every robot stopped before it was), truncations
(``run.max_time`` came) and infos (the last step's say how the run ended). A step
cut short by an end lasts until that instant.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, Generic, TypeVar

import numpy as np
import numpy.typing as npt
from gymnasium.spaces import Space
from pettingzoo import ParallelEnv

from .. import ConfigurationError, RobotId
from ..scenario import RunResult, RunStatus, Scenario, ScenarioRun
from ._episode import Episode, StepOutcome
from ._policy import Act, PolicyLayer, Seat, bind
from ._recipe import Recipe, agent_name
from ._render import draw

__all__ = ["ParallelSwarmEnv"]

L = TypeVar("L", bound=PolicyLayer)
O = TypeVar("O")  # noqa: E741 - the observation type, as gymnasium names it
A = TypeVar("A")

_SEEDS = 2**31
"""Seeds drawn for episodes reset without one are below this."""


class ParallelSwarmEnv(ParallelEnv, Generic[L, O, A]):  # type: ignore[misc] # pettingzoo is untyped
    """A scenario as a PettingZoo ``ParallelEnv`` on virtual time; see the module docs.

    Args:
        scenario: a scenario file, or a loaded :class:`~cas_async.scenario.Scenario`.
        level: the level the policy acts through: its name in the app's ``stack``
            (``"strategy"``) or its index (0 is the top).
        layer: the policy layer: a subclass of :class:`PolicyLayer` and of the
            level's base class, defined at module level (the loader imports it by
            path). ``None``: the class the scenario's ``[layers]`` names for ``level``.
        observe: ``observe(layer)``, an agent's observation, read from its layer
            between steps (the loop is paused: read state, do not await).
        reward: ``reward(layer, outcome)``, an agent's reward for the step.
        observation_space: every agent's observation space (the same object on every call).
        action_space: every agent's action space (the same object on every call).
        dt: simulated seconds per step (a step's end is ``k * dt``, exactly).
        act: ``act(layer, action, context)``: what the layer does when it decides,
            given the action its robot holds then; ``None``: the action itself.
        overrides: ``--set`` strings applied to the scenario (``"robots.count=25"``).
        render_mode: ``"rgb_array"`` for :meth:`render`, or ``None``.
        check: check every action and observation against its space (a clear error
            naming the agent instead of a policy quietly learning from garbage).

    Raises:
        ConfigurationError: ``level``, ``layer``, the spaces or ``dt`` cannot work.
        ScenarioError: the scenario or an override is not valid.
    """

    metadata: ClassVar[dict[str, Any]] = {
        "name": "cas_async_swarm_v0",
        "render_modes": ["rgb_array"],
        "is_parallelizable": True,
    }

    def __init__(
        self,
        scenario: str | os.PathLike[str] | Scenario,
        *,
        level: str | int,
        observe: Callable[[L], O],
        reward: Callable[[L, StepOutcome], float],
        observation_space: Space[O],
        action_space: Space[A],
        dt: float,
        layer: type[L] | None = None,
        act: Callable[[L, A, Any], Any] | None = None,
        overrides: Sequence[str] = (),
        render_mode: str | None = None,
        check: bool = True,
    ) -> None:
        recipe = Recipe(scenario, overrides, level, layer)
        if not (isinstance(dt, int | float) and 0 < dt < float("inf")):
            raise ConfigurationError(f"dt: expected a positive number of seconds, got {dt!r}")
        for name, space in (
            ("observation_space", observation_space),
            ("action_space", action_space),
        ):
            if not isinstance(space, Space):
                raise ConfigurationError(f"{name}: expected a gymnasium Space, got {space!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigurationError(
                f"render_mode: expected one of {self.metadata['render_modes']} or None, "
                f"got {render_mode!r}"
            )
        self._recipe = recipe
        self._observe = observe
        self._reward = reward
        self._act: Act | None = act
        self._observation_space = observation_space
        self._action_space = action_space
        self._dt = float(dt)
        self.render_mode = render_mode
        self._check = check
        seed = recipe.scenario.run.seed
        self._seeds = np.random.default_rng(seed)
        self._episode: Episode | None = None
        self._prepared: tuple[int, Episode] | None = None
        self._seats: dict[str, Seat] = {}
        self._robots: dict[str, RobotId] = {}
        self._steps = 0
        self._done = 0
        self._closed = False
        self.agents: list[str] = []
        # The robots, known once built: the episode built here serves the first reset.
        first = recipe.episode(seed)
        self._prepared = (seed, first)
        self._robots = {agent_name(robot): robot for robot in first.layers}
        self.possible_agents: list[str] = list(self._robots)

    @property
    def dt(self) -> float:
        """Simulated seconds per step."""
        return self._dt

    # -- the spaces -------------------------------------------------------------------------

    def observation_space(self, agent: str) -> Space[O]:
        """The observation space of ``agent``: the one given, the same object every time."""
        return self._observation_space

    def action_space(self, agent: str) -> Space[A]:
        """The action space of ``agent``: the one given, the same object every time."""
        return self._action_space

    @property
    def observation_spaces(self) -> dict[str, Space[O]]:
        """Every possible agent's observation space (for tools that read the dict)."""
        return dict.fromkeys(self.possible_agents, self._observation_space)

    @property
    def action_spaces(self) -> dict[str, Space[A]]:
        """Every possible agent's action space (for tools that read the dict)."""
        return dict.fromkeys(self.possible_agents, self._action_space)

    # -- episodes ---------------------------------------------------------------------------

    def reset(
        self, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[dict[str, O], dict[str, dict[str, Any]]]:
        """Rebuilds the scenario with ``seed``; returns each agent's observation and info.

        The robots are built, not started: the first :meth:`step` starts them with
        its actions in place. Without a seed, the first episode has the scenario's
        own (``run.seed``) and every later one a seed drawn from a generator seeded
        by the last seed given (or the scenario's): a sequence of resets is
        reproducible. ``options`` is accepted and not used. A live episode is
        stopped first.

        Raises:
            RuntimeError: the env is closed.
            ValueError: ``seed`` is negative.
        """
        self._check_open("reset")
        if seed is not None:
            if not isinstance(seed, int | np.integer) or isinstance(seed, bool) or seed < 0:
                raise ValueError(f"reset(): expected a seed of 0 or more, got {seed!r}")
            self._seeds = np.random.default_rng(seed)
            episode_seed = int(seed)
        elif self._episode is None and self._prepared is not None:
            episode_seed = self._prepared[0]
        else:
            episode_seed = int(self._seeds.integers(_SEEDS))
        self._stop_episode()
        prepared, self._prepared = self._prepared, None
        if prepared is not None and prepared[0] == episode_seed:
            episode = prepared[1]
        else:
            if prepared is not None:
                prepared[1].close()
            episode = self._recipe.episode(episode_seed)
        robots = {agent_name(robot): robot for robot in episode.layers}
        if list(robots) != self.possible_agents:
            episode.close()
            raise ConfigurationError(
                f"seed {episode_seed}: the scenario built robots {sorted(episode.layers)}, "
                f"not the env's agents {self.possible_agents}"
            )
        self._episode = episode
        self._robots = robots
        self._seats = {agent: Seat(agent, self._act) for agent in robots}
        for agent, robot in robots.items():
            bind(episode.layers[robot], self._seats[agent])
        self._steps = 0
        self._done = episode.run.objective.progress().done
        self.agents = list(self.possible_agents)
        observations = {agent: self._observation(agent, 0.0) for agent in self.agents}
        infos = {agent: self._info(agent, 0.0, 0) for agent in self.agents}
        return observations, infos

    def step(
        self, actions: Mapping[str, A]
    ) -> tuple[
        dict[str, O],
        dict[str, float],
        dict[str, bool],
        dict[str, bool],
        dict[str, dict[str, Any]],
    ]:
        """Holds each agent's action and advances virtual time by ``dt``; see the module docs.

        Every live agent must act. When the objective completes or ``max_time``
        comes during the step, the step ends there: every agent is terminated or
        truncated, the robots have stopped, and :attr:`agents` is empty.

        Raises:
            RuntimeError: the env is closed, or no episode runs (call :meth:`reset`).
            ValueError: an action is missing, is for no live agent, or is not in
                the action space (with ``check``); an observation is not in the
                observation space.
            EpisodeFailed: a layer raised (the app's, or ``act``).
        """
        self._check_open("step")
        episode = self._episode
        if episode is None or not self.agents:
            raise RuntimeError(
                "step(): no episode runs: call reset() first"
                if episode is None
                else "step(): the episode is over (every agent terminated or truncated): "
                "call reset()"
            )
        self._check_actions(actions)
        for agent, action in actions.items():
            self._seats[agent].hold(action)
        start, end = self._steps * self._dt, (self._steps + 1) * self._dt
        try:
            ended = episode.advance(start, end)
        except BaseException:  # the episode failed, or was interrupted: it is over
            self.agents = []
            raise
        self._steps += 1
        now = end if ended is None else min(end, ended.sim_time)
        done = episode.run.objective.progress().done
        gained, self._done = done - self._done, done
        if ended is None and (
            episode.run.decided is not None or end >= self._recipe.scenario.run.max_time
        ):
            # Decided (a run with a latency runs a moment past it), or past max_time:
            # no action can matter any more, and the episode ends in this step.
            ended = episode.finish()
        status = None if ended is None else ended.status
        complete = status is RunStatus.COMPLETED
        stopped = status is RunStatus.STOPPED
        timed_out = ended is not None and not complete and not stopped
        live = self.agents
        observations, rewards, infos = {}, {}, {}
        for agent in live:
            decisions = self._seats[agent].take_decisions()
            outcome = StepOutcome(
                now,
                now - start,
                done,
                gained,
                episode.run.objective.target,
                complete,
                timed_out,
                decisions,
                episode.environment,
                stopped,
            )
            layer = self.layer(agent)
            rewards[agent] = float(self._reward(layer, outcome))
            observations[agent] = self._observation(agent, now)
            infos[agent] = self._info(agent, now, decisions)
        terminations = dict.fromkeys(live, complete or stopped)
        truncations = dict.fromkeys(live, timed_out)
        if ended is not None:
            self.agents = []
            for info in infos.values():
                info["status"] = str(ended.status)  # how the episode ended
        return observations, rewards, terminations, truncations, infos

    def render(self) -> npt.NDArray[np.uint8]:
        """The run's latest trace sample (every ``run.trace_interval``) as an RGB image.

        Before the first sample, the robots where the Environment has them at 0.

        Raises:
            RuntimeError: the env was made without ``render_mode="rgb_array"``, or no
                episode was reset yet.
        """
        if self.render_mode is None:
            raise RuntimeError(
                "render(): this env has no render_mode: make it with render_mode='rgb_array'"
            )
        episode = self._require_episode("render")
        run = episode.run
        return draw(run.trace, run.environment, run.mission.groups, self._world(), self._title())

    def close(self) -> None:
        """Stops the robots of a live episode and closes its loop; the env is done (idempotent)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._stop_episode()
        finally:
            prepared, self._prepared = self._prepared, None
            if prepared is not None:
                prepared[1].close()

    def __enter__(self) -> ParallelSwarmEnv[L, O, A]:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    # -- what the episode holds -------------------------------------------------------------

    def layer(self, agent: str) -> L:
        """``agent``'s policy layer in the current episode.

        Raises:
            RuntimeError: no episode was reset yet.
            KeyError: ``agent`` is not one of :attr:`possible_agents`.
        """
        episode = self._require_episode("layer")
        layer: L = episode.layers[self.robot_id(agent)]  # type: ignore[assignment]
        return layer

    def robot_id(self, agent: str) -> RobotId:
        """The robot ``agent`` names (``"robot_3"``: 3).

        Raises:
            KeyError: ``agent`` is not one of :attr:`possible_agents`.
        """
        robot = self._robots.get(agent)
        if robot is None:
            raise KeyError(f"{agent!r} is not an agent of this env ({self.possible_agents})")
        return robot

    @property
    def run(self) -> ScenarioRun:
        """The current episode's run: its environment, objective, trace and (once ended) result.

        Raises:
            RuntimeError: no episode was reset yet.
        """
        return self._require_episode("run").run

    @property
    def result(self) -> RunResult | None:
        """What the current episode's run measured, once it ended (``None`` while it runs)."""
        return None if self._episode is None else self._episode.ended

    @property
    def time(self) -> float:
        """The simulated instant the last step ended (0 after a reset)."""
        ended = self.result
        return (
            self._steps * self._dt if ended is None else min(self._steps * self._dt, ended.sim_time)
        )

    # -- internals --------------------------------------------------------------------------

    def _stop_episode(self) -> None:
        episode, self._episode = self._episode, None
        self.agents = []
        if episode is not None:
            episode.stop()

    def _check_open(self, what: str) -> None:
        if self._closed:
            raise RuntimeError(f"{what}(): this env is closed; make a new one")

    def _require_episode(self, what: str) -> Episode:
        self._check_open(what)
        if self._episode is None:
            raise RuntimeError(f"{what}(): no episode yet: call reset() first")
        return self._episode

    def _check_actions(self, actions: Mapping[str, A]) -> None:
        live = set(self.agents)
        missing = [agent for agent in self.agents if agent not in actions]
        if missing:
            raise ValueError(f"step(): no action for {', '.join(missing)} (every live agent acts)")
        extra = sorted(str(agent) for agent in actions if agent not in live)
        if extra:
            raise ValueError(f"step(): {', '.join(extra)} is not a live agent of this episode")
        if self._check:
            space = self._action_space
            for agent, action in actions.items():
                if not space.contains(action):
                    raise ValueError(
                        f"step(): the action for {agent}, {action!r}, is not in {space}"
                    )

    def _observation(self, agent: str, t: float) -> O:
        observation = self._observe(self.layer(agent))
        if self._check and not self._observation_space.contains(observation):
            raise ValueError(
                f"observe() returned an observation for {agent} at t = {t:g} s that is not in "
                f"{self._observation_space}: {observation!r}"
            )
        return observation

    def _info(self, agent: str, t: float, decisions: int) -> dict[str, Any]:
        return {"robot": self._robots[agent], "time": t, "decisions": decisions}

    def _world(self) -> tuple[float, float]:
        world = self._recipe.scenario.world
        return (world.width, world.height)

    def _title(self) -> str:
        seed = self.run.result.seed
        return f"{self._recipe.scenario.app.name}, seed {seed}: t = {self.time:g} s"
