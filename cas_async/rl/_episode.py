"""One episode: a scenario's run on its own stepping loop, advanced one step at a time.

An :class:`Episode` builds the run (robots not started), starts it at the first
step and then runs its loop up to each step's end (see :mod:`._loop`). The whole
run is one task, exactly the coroutine a plain run is (``async with run: await
run.until_done()``), so an episode whose policy makes the app's own choices runs
as the app alone does, to the last bit.

Each episode has a loop of its own, whose virtual clock starts at 0.0: an episode
with a seed is the same whichever episodes came before it.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import final

from .. import CasError, ConfigurationError, RobotId, RobotStateError
from ..scenario import RunResult, RunStatus, Scenario, ScenarioRun
from ..sim import Environment
from ._policy import ACTION_TIMER, PolicyLayer, acts_every_step
from ._stepping_loop import SteppingLoop, off_running_loop

__all__ = ["Episode", "EpisodeFailed", "StepOutcome"]


class EpisodeFailed(CasError):
    """The episode's run failed: a layer raised (the app's, or the policy's ``act``).

    The message names the robot, the layer and the error, with its traceback.
    """


@dataclass(frozen=True, slots=True)
class StepOutcome:
    """What one step did, as ``reward(layer, outcome)`` sees it (one per agent).

    Attributes:
        time: the simulated instant the step ended (the instant the objective was
            complete or ``max_time`` came, for a last step cut short).
        dt: how long the step lasted, in simulated seconds.
        done: the objective's progress at the end (``Tally.done``: buckets delivered,
            robots gathered).
        gained: how much of ``done`` this step added (negative if it went back).
        target: how much the objective needs to be complete.
        complete: the objective is complete: the episode terminated.
        timed_out: ``run.max_time`` came first: the episode was truncated.
        stopped: every robot stopped before the objective was complete: the
            episode terminated (see :class:`~cas_async.scenario.RunStatus`).
        decisions: how many decisions this agent's layer took during the step.
        environment: the run's Environment (positions at ``time``, items).
    """

    time: float
    dt: float
    done: int
    gained: int
    target: int
    complete: bool
    timed_out: bool
    decisions: int
    environment: Environment
    stopped: bool = False


@final
class Episode:
    """One run of a scenario, stepped; see the module docs.

    Args:
        scenario: the scenario, its ``[layers]`` putting a policy layer at ``level``.
        level: the index of the policy's level in the stack.

    Raises:
        ConfigurationError: a robot's layer at ``level`` is not a :class:`PolicyLayer`.
    """

    def __init__(self, scenario: Scenario, level: int) -> None:
        self._loop = SteppingLoop()
        try:
            self._run = ScenarioRun(scenario)
        except BaseException:
            self._loop.close()
            raise
        layers: dict[RobotId, PolicyLayer] = {}
        for robot in self._run.mission.robots:
            layer = robot.layers[level]
            if not isinstance(layer, PolicyLayer):  # the loader put the class there
                self._loop.close()
                raise ConfigurationError(
                    f"robot {robot.robot_id}: level {level} is {type(layer).__qualname__}, "
                    "not a PolicyLayer"
                )
            layers[robot.robot_id] = layer
        self.layers = layers
        """The policy layer of every robot, by robot id, in the order the app built them."""
        self._stepped = [layer for layer in layers.values() if acts_every_step(layer)]
        self._driver: asyncio.Task[RunResult] | None = None
        self._result: RunResult | None = None
        self._closed = False

    @property
    def run(self) -> ScenarioRun:
        """The scenario's run: its environment, objective, trace and result."""
        return self._run

    @property
    def environment(self) -> Environment:
        """The run's Environment."""
        return self._run.environment

    @property
    def ended(self) -> RunResult | None:
        """The run's result once it ended (complete, timed out, failed), else ``None``."""
        return self._result

    def advance(self, start: float, end: float) -> RunResult | None:
        """Runs the step from ``start`` to ``end``: the robots start at the first one.

        Layers that act on every action are woken at ``start``. Returns the run's
        result when it ended during the step (then the robots have stopped).

        Raises:
            EpisodeFailed: a layer raised.
        """
        if self._result is not None or self._closed:
            raise RuntimeError("the episode is over")
        loop = self._loop
        if self._driver is None:
            self._driver = loop.create_task(self._whole_run())
        elif self._stepped:
            loop.call_soon(self._wake, start)
        driver = self._driver
        off_running_loop(lambda: loop.run_until(end, driver))
        if not driver.done():
            return None
        return self._end(driver)

    async def _whole_run(self) -> RunResult:
        """The run as a plain run is: started, run to its end, stopped."""
        async with self._run:
            self._wake(0.0)  # no await in between: the robots' order of events is kept
            return await self._run.until_done()

    def _wake(self, at: float) -> None:
        """Tells the layers that act on every action that one arrived (at instant ``at``)."""
        for layer in self._stepped:
            with contextlib.suppress(RobotStateError):  # a robot that stopped takes none
                layer.wake_at(at, ACTION_TIMER)

    def _end(self, driver: asyncio.Task[RunResult]) -> RunResult:
        try:
            result = driver.result()
        finally:
            self.close()
        self._result = result
        if result.status is RunStatus.FAILED:
            raise EpisodeFailed(
                f"the run failed at t = {result.sim_time:g} s: {result.error}\n{result.traceback}"
            )
        return result

    def finish(self) -> RunResult:
        """Runs the episode to its own end without more steps; returns the result.

        For a run decided already (completed, or every robot stopped: a run
        observed window by window runs a moment on), or past ``run.max_time``: no
        action can matter any more, and the run ends by its own rule.

        Raises:
            EpisodeFailed: a layer raised.
        """
        if self._result is not None or self._closed or self._driver is None:
            raise RuntimeError("the episode is over, or never started")
        driver = self._driver
        off_running_loop(lambda: self._loop.run_until(math.inf, driver))
        return self._end(driver)

    def stop(self) -> None:
        """Stops the robots where they are (the run ends as interrupted), and closes the loop."""
        if self._closed:
            return
        driver = self._driver
        try:
            if driver is not None and not driver.done():
                self._loop.call_soon(self._run.interrupt)
                off_running_loop(lambda: self._loop.run_until(math.inf, driver))
                self._result = driver.result()
        finally:
            self.close()

    def close(self) -> None:
        """Closes the loop once its run has ended or never started (idempotent)."""
        if self._closed:
            return
        self._closed = True
        loop = self._loop

        def finish() -> None:
            _cancel(asyncio.all_tasks(loop), loop)
            loop.run_until_complete(loop.shutdown_asyncgens())

        try:
            off_running_loop(finish)
        finally:
            loop.close()


def _cancel(tasks: Iterable[asyncio.Task[object]], loop: SteppingLoop) -> None:
    """Cancels what is left on the loop and lets it finish (nothing should be left)."""
    pending: Sequence[asyncio.Task[object]] = [task for task in tasks if not task.done()]
    if not pending:
        return
    for task in pending:
        task.cancel()
    loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
