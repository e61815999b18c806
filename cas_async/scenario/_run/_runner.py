"""Running a loaded scenario: clock, transport, Environment, the app's swarm, and measuring it.

:class:`ScenarioRun` takes the steps of a run one by one, for a caller that acts
between them (the CLI, which adds argument parsing, signals and output files,
writes the results before the robots stop); ``run_scenario`` (:mod:`._run_scenario`)
is the whole run as one coroutine.
The run ends when the mission's objective is complete (see
:mod:`~cas_async.scenario._spec._objective`: the Fire Brigade's is a number of items
retired), when ``run.max_time`` simulated seconds have passed, when ``stop`` is
set (Ctrl-C), or when a layer fails; in every case the result says which, and
holds what was measured up to then. The runner itself knows no kind of work:
progress, completion, the invariant checked at every sample and the mission's
own results are the objective's.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Callable
from pathlib import Path
from typing import TextIO, final

import numpy as np
import numpy.typing as npt

from ..._core._gc_policy import while_building, young_generation_for
from ..._core._swarm import Swarm
from ..._errors import ConfigurationError, LayerError
from ..._types import RobotId
from ..._wire._swarm_key import SwarmKey
from ...sim._environment import Environment
from .._processes._world import World
from .._spec._app import Mission, objective_of
from .._spec._layers import check_built
from .._spec._loader import Scenario
from .._spec._objective import CallbackWatch, Objective
from ..output._progress import Progress
from ..output._results import RunProgress, RunResult, RunStatus
from ..output._trace import Trace, TraceCsv
from ._listener import Listeners, RunListener
from ._measure import PositionMeasures, mark_failed, measure_end
from ._placement import Sampling, place, transport_for

__all__ = ["ScenarioRun"]


@final
class ScenarioRun:
    """One run of a loaded scenario, step by step.

    :func:`run_scenario` takes every step at once. A caller that must act between
    them (the command line writes its results before the robots stop) takes them
    one by one::

        run = ScenarioRun(scenario, stop=stop)   # builds the robots: synchronous
        async with run:                          # starts them
            result = await run.until_done()      # the run ended: what it measured
            ...                                  # the robots still exist, stopped or not
        # leaving stops and closes the robots, and completes ``run.result``

    Building needs no running loop, so it can happen before one starts (where a
    signal can interrupt it: the loop cannot run while a synchronous build does).

    Args:
        scenario: a loaded, validated scenario.
        key: the swarm key: every datagram is signed and checked (see
            :class:`~cas_async.transport._authenticated.AuthenticatedTransport`).
        progress_to: where to show progress while running (simulated time, items
            delivered, exchanges): a live line on a terminal, plain lines otherwise.
        stop: when set, the run stops early with status INTERRUPTED; set while the
            robots start, it cancels the start.
        observe: called with the Environment once the robots are in it, before they
            start (a test can subscribe to ``environment.items`` there, for instance).
        wall_clock: measures the wall time, from building to the end.
        trace_csv: where to write the trace as CSV (see :class:`TraceCsv`): as the
            run goes, so that little is left to write when it ends; the file is in
            place once the run ended (:meth:`until_done`, :meth:`interrupt`), and
            is not written at all when the robots never started.

    Raises:
        ConfigurationError: the scenario cannot run with ``key``.
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        key: SwarmKey | None = None,
        progress_to: TextIO | None = None,
        stop: asyncio.Event | None = None,
        observe: Callable[[Environment], None] | None = None,
        wall_clock: Callable[[], float] = time.perf_counter,
        trace_csv: Path | None = None,
        world: World | None = None,
    ) -> None:
        self._wall_clock = wall_clock
        self._trace_path = trace_csv
        self._trace_csv: TraceCsv | None = None
        self._started = wall_clock()
        self._scenario = scenario
        self._stop = asyncio.Event() if stop is None else stop  # interrupt() sets it too
        run = scenario.run
        self._clock = clock = scenario.clock()
        environment = scenario.environment(clock)
        self._complete = asyncio.Event()
        self._listeners = Listeners()
        transport = transport_for(scenario, clock, key, world, environment)
        with while_building():
            # A world runs no robot: its workers do (an app that asks holds() builds none).
            share = None if world is None else frozenset[RobotId]()
            setup = scenario.setup(environment, clock, transport, share)
            self._mission = mission = scenario.app.build(setup)
        try:
            check_built(getattr(scenario.app, "stack", ()), scenario.layers, mission.robots)
        except ConfigurationError as error:
            raise ConfigurationError(f"{scenario.path}: {error}") from None
        self._objective = objective = objective_of(
            mission, scenario.app.name, getattr(scenario.app, "item_name", "item")
        )
        sampling = Sampling(
            clock=clock,
            max_time=run.max_time,
            interval=run.trace_interval,
            sample=self._sample,
            hold=self._listeners.hold,
            sample_held=self._sample_held,
            behind=self._fell_behind,
            done=self._complete.is_set,
        )
        # Where the robots run: here (sampled, or in windows), or in a world's workers.
        self._placement = placement = place(
            scenario, environment, transport, mission, objective, sampling, world
        )
        self.environment = environment = placement.environment
        """What the run observes of its robots: their poses, motions and items.

        With a network latency on virtual time (and an objective that reads only
        the Environment), or across processes, a mirror of the robots' own, which
        follows them window by window (see :mod:`cas_async.scenario._processes._observer`);
        else theirs."""
        self._progress = None
        if progress_to is not None:
            self._progress = Progress(
                progress_to,
                target=objective.target,
                item_name=objective.noun,
                interval=run.progress_interval,
                detail=objective.detail,
            )
        self.result = RunResult(
            scenario=str(scenario.path),
            app=scenario.app.name,
            item_name=objective.noun,
            seed=run.seed,
            target=objective.target,
            groups={label: list(ids) for label, ids in mission.groups.items()},
            config=scenario.data,
            kind=objective.kind,
            verb=objective.verb,
            detail=objective.detail,
        )
        """What the run measured: complete once the robots have stopped."""
        self._behind = 0.0  # simulated seconds the latest sample came after its instant
        self.trace = Trace(environment.robot_ids)
        """Where the robots were over simulated time."""
        self._measures = PositionMeasures(mission, self.trace.ids)
        self._rows = np.array(self.trace.ids, dtype=np.int64)
        self._watch = CallbackWatch(
            environment,
            clock,
            changed=self._changed,
            completed=self._completed,
            exchanged=self._exchanged,
        )
        objective.attach(self._watch)
        if observe is not None:
            observe(environment)
        self._started_swarm = False
        self._ended = False
        self._gc = contextlib.ExitStack()

    def _changed(self, t: float) -> None:
        if self._progress is not None and not self._ended:
            done, detail = self._objective.progress()
            self._progress.update(t, done, detail)
        if not self._ended:
            self._listeners.changed(t)

    def _completed(self, t: float) -> None:
        if self._ended or self._complete.is_set():  # what comes after is not the run's
            return
        self.result.makespan = t
        self._complete.set()

    def _exchanged(self, t: float, count: int) -> None:
        if self._ended or self._complete.is_set() or not self._scenario.run.trace_exchanges:
            return
        xy = self.environment.positions_at(t).xy
        self.trace.exchange(t, count, xy, self._carrying())
        self._measures.exchanged(xy)

    def now(self) -> float:
        """Simulated seconds since the robots started: 0 before, the end's instant after.

        Call it on the run's own loop (where it runs); from another thread, see
        :class:`~cas_async.scenario.BackgroundRun`.
        """
        if self._ended:
            return self.result.sim_time
        return self._clock.now() if self._started_swarm else 0.0

    def progress(self) -> RunProgress:
        """Where the run stands now: simulated time, done of the target, how it ended.

        On the run's loop, as :meth:`now`.
        """
        done, detail = self._objective.progress()
        status = self.result.status if self._ended else None
        return RunProgress(self.now(), done, self._objective.target, detail, status)

    @property
    def mission(self) -> Mission:
        """What the application built: its robots, target, groups and measures."""
        return self._mission

    @property
    def objective(self) -> Objective:
        """What the mission is for: :class:`Items` unless the application chose its own."""
        return self._objective

    def listen(self, listener: RunListener) -> None:
        """Adds ``listener``: it hears every sample and progress change from now on."""
        self._listeners.add(listener)

    @property
    def swarm(self) -> Swarm:
        """The robots the application built, as one swarm (started by ``async with``)."""
        return self._placement.swarm

    async def __aenter__(self) -> ScenarioRun:
        """Starts the robots; when ``stop`` is set meanwhile, the start is undone instead."""
        # While the swarm runs, the collector's youngest generation is sized to it: to
        # every robot the run simulates or observes (a world observes its workers' robots).
        robots = max(len(self._placement.swarm), len(self._placement.environment))
        self._gc.enter_context(young_generation_for(robots))
        try:
            self._placement.arm()  # before any robot's first instant
            starting = asyncio.ensure_future(self._placement.start())
            stopped = asyncio.ensure_future(self._stop.wait())
            try:
                await asyncio.wait((starting, stopped), return_when=asyncio.FIRST_COMPLETED)
            finally:
                stopped.cancel()
                if not starting.done():
                    starting.cancel()  # the swarm closes what it had opened
                    with contextlib.suppress(asyncio.CancelledError):
                        await starting
            if starting.cancelled():
                return self
            starting.result()  # its error, if the start failed
            self._started_swarm = True
            if self._trace_path is not None and not self._ended:  # not interrupted meanwhile
                self._trace_csv = TraceCsv(self.trace, self._trace_path)
        except BaseException as exc:  # no __aexit__ follows a failed __aenter__: undo here
            await self.__aexit__(type(exc), exc, exc.__traceback__)
            raise
        return self

    @property
    def decided(self) -> RunStatus | None:
        """How the run ends, as soon as that is known: completed or stopped, else ``None``.

        A run observed window by window (a latency on virtual time) is decided
        before it ends: its robots run on ``run.credit`` past that instant, as a run
        across processes does. :attr:`result` is final only once the run ended.
        """
        if self._complete.is_set():
            return RunStatus.COMPLETED
        return self._placement.decided()

    async def until_done(self) -> RunResult:
        """Runs until the target, ``max_time``, ``stop`` or a failure; measures; returns the result.

        The robots are not stopped yet: leaving the ``async with`` block does that.
        """
        if self._ended:
            return self.result
        if not self._started_swarm:  # stopped while starting
            return self._end(RunStatus.INTERRUPTED, None)
        try:
            status, failure = await self._placement.until_done(self._complete, self._stop)
        except LayerError as error:  # the swarm's, raised again as its task is awaited
            status, failure = RunStatus.FAILED, error
        except BaseException:
            self._close_progress(final=False)
            raise
        return self._end(status, failure)

    def failed_to_start(self, error: BaseException) -> RunResult:
        """The run as it ends when its robots could not start: failed, with ``error``.

        For a start refused (a transport, a clock, a world whose workers did not
        come): one line says why (``error``), no traceback.
        """
        result = self._end(RunStatus.FAILED, error)
        result.traceback = None
        return result

    def interrupt(self) -> RunResult:
        """Ends the run where it stands, as a set ``stop`` does, but at once; returns the result.

        For a loop callback that must not wait for the stop to be seen: the result is
        final now (:meth:`until_done` returns it); robots here run until the ``async
        with`` block is left; a world's workers are told to stop, its children killed.
        """
        self._stop.set()
        self._placement.abandon()
        return self._end(RunStatus.INTERRUPTED, None)

    def _end(self, status: RunStatus, failure: BaseException | None) -> RunResult:
        """Measures the run as it ended, once; later calls return the same result."""
        result = self.result
        if self._ended:
            return result
        self._ended = True
        self._placement.ended(status)
        result.status = status
        if failure is not None:
            mark_failed(result, failure)
        measure_end(
            result,
            self._mission,
            self._objective,
            self._placement.message_counts(),
            self.environment,
            self._end_instant(status),
        )
        if status is RunStatus.COMPLETED and result.makespan is not None:
            self._sample_last(result.makespan)  # the trace ends where the mission did
        elif status is RunStatus.STOPPED:
            self._sample_last(result.sim_time)  # ... or where the robots stopped
        self._measures.write(result, self.trace)
        result.extra.update(self._placement.stats())
        if not self._scenario.run.virtual:  # how far the run fell behind the wall clock
            result.extra["behind_s"] = round(self._behind, 3)
        self._count_faults()
        if self._trace_csv is not None:
            try:
                self._trace_csv.close()
            except BaseException:
                self._trace_csv.discard()
                raise
        result.wall_time = self._wall_clock() - self._started
        self._close_progress(final=True)
        return result

    @property
    def trace_csv(self) -> Path | None:
        """The trace's CSV file, once written (see the ``trace_csv`` argument)."""
        if self._trace_csv is None or not self._ended:
            return None
        return self._trace_csv.path

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: object
    ) -> None:
        """Stops and closes the robots; a layer failure found on the way fails the result."""
        try:
            if self._started_swarm:
                await self._placement.stop(exc_type, exc, tb)
        except LayerError as error:  # a failure that running did not raise
            mark_failed(self.result, error)
        finally:
            await self._placement.close(hurry=self._stop.is_set())
            self._gc.close()
            if self._trace_csv is not None and not self._ended:
                self._trace_csv.discard()  # the run ended by an exception: no trace
            self._close_progress(final=False)
            self._count_faults()  # read after the swarm closed its endpoints
            if not self._ended:  # else measured when it ended: stopping is not the run's
                self.result.wall_time = self._wall_clock() - self._started

    def _fell_behind(self, seconds: float) -> None:
        self._behind = max(self._behind, seconds)

    def _sample(self, t: float) -> None:
        if self._ended:
            return
        objective = self._objective
        self._watch.sampling(t)
        try:
            objective.check()  # the full audit of the mission's invariant, as of t
        finally:
            self._watch.sampling(None)
        carrying = self._carrying()
        xy = self.environment.positions_at(t).xy
        self.trace.sample(t, xy, carrying)
        self._measures.sampled(xy)
        self._listeners.sampled(t, self.trace.at_time(t), carrying)  # the trace's own copy
        if self._progress is not None:
            done, detail = objective.progress()
            self._progress.update(t, done, detail)
        if self._trace_csv is not None:
            self._trace_csv.write_until(t)  # what came before this sample is final

    def _end_instant(self, status: RunStatus) -> float:
        """The simulated instant the run ended at, as its results count it.

        Observed window by window (a latency on virtual time, in one process or
        many), the run is measured where its mirror is: at the completion, at
        ``max_time``, where the last robot stopped, or at the last window's end,
        the same for any number of processes. Otherwise, now.
        """
        observed = self._placement.observed_until()
        if observed is None:
            return self._clock.now()
        if status is RunStatus.COMPLETED and self.result.makespan is not None:
            return self.result.makespan
        if status is RunStatus.TIMED_OUT:
            return self._scenario.run.max_time
        return observed

    async def _sample_held(self, t: float) -> None:
        """A sample at ``t``, then what the listeners hold the run for (a paced view)."""
        self._sample(t)
        await self._listeners.hold(t)

    def _sample_last(self, t: float) -> None:
        """A last regular sample at ``t``, unless one was taken there (or later)."""
        times = self.trace.times
        if not len(times) or times[-1] < t:
            carrying = self._carrying()
            self.trace.sample(t, self.environment.positions_at(t).xy, carrying)
            self._listeners.sampled(t, self.trace.at_time(t), carrying)  # the views' last frame

    def _carrying(self) -> npt.NDArray[np.bool_]:
        """Which robots of the trace carry something now, in the trace's row order."""
        return np.isin(self._rows, np.fromiter(self._objective.carrying(), dtype=np.int64))

    def _count_faults(self) -> None:
        self.result.faults = self._placement.fault_counts()

    def _close_progress(self, *, final: bool) -> None:
        if self._progress is not None:
            self._progress.close(final=final)
            self._progress = None
