"""The world process of a run across processes: it shares the robots out, and observes them.

The **world** (plugged into :class:`~cas_async.scenario.ScenarioRun`) builds the
scenario like a run in one process (the mission: its robots, objective and
groups) but starts no robot. It runs a Zenoh router the workers connect to, deals
the robots out (:mod:`._partition`), starts the workers (``run --processes``) or
waits for them (``python -m cas_async world``), and observes: the records of every
worker's :class:`~._control.Window` go to the run's :class:`~._observer.Observer`
up to the least end any worker reached, in the one order a run in one process
applies them too, and the world grants the workers steps of ``run.credit``
ahead of it, or stops the run.

Nothing else goes through the world: robots talk to robots, and hand items over,
worker to worker. A worker that exits, or goes quiet for ``run.window_limit``
wall seconds, ends the run as failed, naming it and its robots, and every run
leaves a ``results.json`` (the CLI writes it).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import secrets
import time
from collections.abc import Callable, Iterable
from typing import Any, Final

from ..._core._transport_contract import Transport
from ..._errors import ConfigurationError
from ..._time._clock import Clock, ScaledClock
from ..._types import RobotId
from ..._wire._swarm_key import SwarmKey
from ...sim._environment import Environment
from ...transport._memory import MemoryTransport
from ...transport.zenoh import import_zenoh, loopback_config
from ...transport.zenoh._sessions import with_free_port
from .._spec._app import Mission
from .._spec._app_import import robot_counts
from .._spec._capacity import Capacity, processes_problem
from .._spec._loader import DEFAULT_LATENCY, Scenario
from ..output._results import RunStatus
from ._children import Children
from ._control import (
    BEAT_EVERY,
    HURRY_LIMIT,
    WORLD,
    Beat,
    Bye,
    Channel,
    Control,
    Counts,
    Failed,
    Go,
    Grant,
    Ready,
    Stop,
    Window,
)
from ._halo import epoch_steps, top_speed
from ._liveness import Liveness
from ._lobby import Lobby
from ._lost import WorkerLost, WorkerRefused
from ._observer import Observation, Observer
from ._partition import lost_robots, partition
from ._tally import summed_faults, summed_messages
from ._window_costs import WindowCosts
from ._windows import Steps

__all__ = ["World"]

GO_AHEAD: Final = 0.5
"""Wall seconds from the world's :class:`Go` to the epoch it names (scaled time)."""
STOP_LIMIT: Final = 10.0
"""Wall seconds the world waits for its workers' last counts, all together."""


class World:
    """The world process's side of a run across processes (see the module docs).

    Args:
        scenario: the loaded scenario.
        workers: how many worker processes run the robots.
        key: the swarm key; a random one is made for workers spawned here.
        listen: the Zenoh endpoint the world's router listens on.
        spawn: start the workers here as child processes (``--processes``), or
            wait for workers started elsewhere (``python -m cas_async world``).

    Raises:
        ConfigurationError: fewer than one worker, or Zenoh is not installed.
    """

    def __init__(
        self,
        scenario: Scenario,
        *,
        workers: int,
        key: SwarmKey | None,
        listen: str = "tcp/127.0.0.1:0",
        spawn: bool = True,
    ) -> None:
        if workers < 1:
            raise ConfigurationError(f"a run across processes needs >= 1 worker, got {workers}")
        problem = processes_problem(
            robot_counts(scenario.app, scenario.app_path, scenario.config),
            workers,
            Capacity.of_this_machine(),
            samples=scenario.run.max_time / scenario.run.trace_interval,
        )
        if problem is not None:
            raise ConfigurationError(f"{scenario.path}: {problem}")
        if scenario.network.latency <= 0:
            raise ConfigurationError(
                f"{scenario.path}: network.latency = 0 runs in one process only: a run across "
                "processes needs a latency > 0, the simulated time a process may run ahead of "
                "the others without hearing from them (leave it out for the default, "
                f"{DEFAULT_LATENCY} s)"
            )
        import_zenoh()  # a clear error now, before anything starts
        if key is None and spawn:
            key = SwarmKey(secrets.token_bytes(32))
        self._scenario = scenario
        self._workers = workers
        self._key = key
        self._listen = listen
        self._spawn = spawn
        self.namespace = f"cas_async/run/{secrets.token_hex(8)}"
        self._session: Any = None
        self._channel: Channel | None = None
        self._lobby: Lobby | None = None
        self._children = Children(self._exited)
        self._watchers: list[asyncio.Task[None]] = []
        self._ready: set[int] = set()
        self._counts: dict[int, Counts] = {}
        self._byes: set[int] = set()
        self._latest: dict[int, Window] = {}  # a worker -> its latest window (virtual time)
        self._pending: list[Observation] = []  # records not observed yet (virtual time)
        self._effects_until = -math.inf  # the latest effect sent before max_time (see _quiet)
        self._flowing: list[Observation] = []  # scaled time: records not applied yet
        self._heard: dict[int, float] = {}  # scaled time: each worker's simulated time heard
        self._stopped_at: dict[int, float] = {}  # scaled time: when each one's robots stopped
        self._liveness = Liveness(
            workers,
            scenario.run.window_limit,
            lambda who: lost_robots(self._shares, who),
            self.tick,
        )
        self._beaten = 0.0  # when the world last said it lives (Beat)
        self._token_of_world: Any = None
        self._lost: BaseException | None = None
        self._news: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._pids: dict[int, int] = {}  # a worker's process id (its hello's) -> its index
        self._shares: list[list[RobotId]] = []
        self._costs = WindowCosts()  # rounds, cross-process effects, waits (see stats)
        self._epoch_steps = 0  # with an interaction range: steps per epoch (see _halo)
        self.endpoint = ""
        """Where the router listens, once started."""

    # -- what ScenarioRun asks -------------------------------------------------------

    def transport(self) -> Transport:
        """What the world's own copies of the robots are built with: they never start."""
        return MemoryTransport()

    def adopt(self, environment: Environment, mission: Mission) -> None:
        """Takes the built mission: the robots are shared out by the scenario's partition.

        Raises:
            ConfigurationError: more workers than robots, or the app's partition is wrong.
        """
        ids = list(environment.robot_ids)  # every robot, built here or not (holds())
        limit, scenario = environment.interaction_range, self._scenario
        if limit is not None and scenario.run.virtual:  # the workers' epochs (see _halo)
            speed, latency = top_speed(environment), scenario.network.latency
            self._epoch_steps = epoch_steps(limit, speed, latency, scenario.credit)
        try:
            self._shares = partition(
                environment, ids, self._workers, self._scenario.run.partition, self._scenario.app
            )
        except ValueError as exc:
            raise ConfigurationError(f"{self._scenario.path}: --processes: {exc}") from None

    @property
    def shares(self) -> list[list[RobotId]]:
        """The robots each worker runs."""
        return [list(share) for share in self._shares]

    async def start(self, clock: Clock) -> None:
        """Opens the router, starts (or awaits) the workers, and starts the run.

        On scaled time the run starts at a wall-clock instant a moment ahead (the
        epoch its :class:`Go` names): the workers' clocks and ``clock``, the
        world's own, all start at it, and this returns once it has come, so that
        the world's samples and progress are labelled with the robots' time.

        Raises:
            ConfigurationError: the router cannot listen.
            WorkerLost: a worker exited or did not get ready within ``run.window_limit``.
        """
        self._news = asyncio.Event()
        self._loop = asyncio.get_running_loop()
        if not self._scenario.run.virtual:  # else the held loop ticks
            self._watchers.append(asyncio.ensure_future(self._ticking()))
        zenoh = import_zenoh()
        self.endpoint = with_free_port(self._listen)
        config = loopback_config(mode="router", listen=[self.endpoint])
        try:
            self._session = await asyncio.to_thread(zenoh.open, config)
        except Exception as exc:
            raise ConfigurationError(f"world: cannot listen on {self.endpoint}: {exc}") from exc
        self._lobby = Lobby(
            self._session,
            self._key,
            self._scenario,
            self._workers,
            self.namespace,
            lambda: self.shares,
            self._joined,
        )
        self._channel = channel = Channel(
            self._session, self.namespace, WORLD, self._key, self._on_message
        )
        channel.listen("world")
        channel.listen("win/*")
        self._token_of_world = self._session.liveliness().declare_token(f"{self.namespace}/world")
        self._liveness.watch(self._session, self.namespace)
        if self._spawn:
            await self._children.spawn(self._workers, self.endpoint, self._key)
        limit = self._scenario.run.window_limit
        await self._until(lambda: len(self._ready) >= self._workers, limit, "workers to be ready")
        if self._scenario.run.virtual:
            channel.send("all", Go(0.0))
            return
        epoch = time.time() + GO_AHEAD
        if isinstance(clock, ScaledClock):
            clock.start_at_wall(epoch)
        channel.send("all", Go(epoch))
        await clock.sleep_until(0.0)  # nothing before time 0: the robots start then

    async def coordinate(
        self, observer: Observer, done: Callable[[], bool], stop: asyncio.Event
    ) -> tuple[RunStatus, BaseException | None]:
        """Observes the workers' windows and lets them run on, until the run ends (virtual time).

        Each worker runs its own windows, waiting only for the workers its robots
        can hear from (see :mod:`._control`); the world observes every record before
        the earliest window end of all (:attr:`Window.until`), in the one order a run
        in one process does, and lets the workers run a step past the step of what
        it observed (:class:`~._control.Grant`, steps of ``run.credit``): it is not
        on their way. Once a record decides the run at ``t`` (its mission complete,
        or every robot stopped before it was; records after that instant are not
        observed), the workers run every event before the end of the step after
        ``t``'s, unobserved, and no later one, as a run in one process does (see
        :mod:`.._run._windowed`): both measure the same.
        """
        scenario, channel, news = self._scenario, self._channel, self._news
        assert channel is not None and news is not None  # noqa: PT018
        max_time = scenario.run.max_time
        steps = Steps(scenario.credit, scenario.network.latency, max_time, self._epoch_steps)
        granted = 2  # what every worker may run from the start (see _worker)
        verdict: RunStatus | None = None
        ends_at, last_step = math.inf, 0  # once decided: the run ends at the end of last_step
        observed, since = 0.0, time.monotonic()  # observed up to; since when (for silence)
        while True:
            if self._lost is not None:
                return RunStatus.FAILED, self._lost
            if stop.is_set():
                return RunStatus.INTERRUPTED, None
            latest = self._latest
            until = min((w.until for w in latest.values()), default=0.0)
            if len(latest) < self._workers:
                until = 0.0
            if until > observed:
                observed, since = until, time.monotonic()
                began = time.perf_counter()
                if verdict is None:
                    verdict, decided_at = await self._observe(observer, until, done)
                    if verdict is not None:
                        ends_at = steps.end_of_run(decided_at)
                        last_step = steps.step_of(decided_at) + 2
                    elif until >= max_time or self._quiet(until, max_time):
                        await observer.sample_until(max_time, inclusive=False)
                        self._costs.observed(time.perf_counter() - began)
                        return RunStatus.TIMED_OUT, None
                self._costs.observed(time.perf_counter() - began)
                if verdict is not None and until >= ends_at:
                    return verdict, None  # every event before the end ran: none after it
                # The workers may run into the step after the one observed, never past the end.
                cap = steps.step_of(until) + 2 if verdict is None else last_step
                if cap > granted:
                    granted = cap
                    channel.send("all", Grant(granted))
            behind = [
                w for w in range(self._workers) if w not in latest or latest[w].until <= until
            ]
            silent = self._liveness.silent(behind, since)  # the others wait for those
            if silent:
                where = f" at simulated time {until:g}"
                return RunStatus.FAILED, self._liveness.lost(silent, where)
            news.clear()
            await news.wait()  # news, or a tick (see tick): the wall clock is looked at again

    async def _observe(
        self, observer: Observer, until: float, done: Callable[[], bool]
    ) -> tuple[RunStatus | None, float]:
        """Observes every record before ``until``: whether that decided the run, and when.

        Once every worker's robots have stopped, and every record up to the instant the
        last one did is in, the records are observed up to that instant and the run is
        decided there: completed if its objective was met by then (a tie goes to the
        objective), else stopped.
        """
        pending = self._pending
        stopped_at = _all_stopped(self._latest.values())
        if stopped_at is not None and until > stopped_at:
            self._pending = []
            await observer.window(stopped_at, [o.split(stopped_at)[0] for o in pending])
            if done():
                return RunStatus.COMPLETED, _completed_at(observer)
            return RunStatus.STOPPED, stopped_at
        ready: list[Observation] = []
        self._pending = []
        for observation in pending:
            now, later = observation.before(until)
            ready.append(now)
            if later:
                self._pending.append(later)
        await observer.window(until, ready)
        if done():
            return RunStatus.COMPLETED, _completed_at(observer)
        return None, until

    def _quiet(self, until: float, max_time: float) -> bool:
        """Whether nothing happens before ``max_time`` any more (all observed up to ``until``).

        Every worker's next event is at ``max_time`` or later, and every effect they
        sent each other (datagrams, hand-overs, motions seen) came before ``until``,
        so that it ran: nothing can start anything again.
        """
        soonest = min(window.next_event for window in self._latest.values())
        return soonest >= max_time and self._effects_until < until

    async def follow(self, observer: Observer) -> None:
        """Applies what the workers report as it comes (scaled time); raises when one is lost.

        A record is applied once every worker has reported up to its instant, so
        that records come to the observer in order even from different workers.
        Returns once every worker's robots have stopped and everything up to the
        instant the last of them did is applied: the run then decides how it ended.

        Raises:
            WorkerLost: a worker exited or failed.
        """
        news = self._news
        assert news is not None
        started = time.monotonic()
        while True:
            if self._lost is not None:
                raise self._lost
            silent = self._liveness.silent(range(self._workers), started)
            if silent:  # a worker reports every HEARTBEAT: this one stopped
                raise self._liveness.lost(silent)
            stopped = self._stopped_at
            all_stopped = len(stopped) == self._workers
            if len(self._heard) == self._workers:
                horizon = min(self._heard.values())
                if all_stopped:
                    horizon = min(horizon, max(stopped.values()))
                if self._flowing:
                    ready, later = [], []
                    for observation in self._flowing:
                        split = observation.split(horizon)
                        ready.append(split[0])
                        if split[1]:
                            later.append(split[1])
                    self._flowing = later
                    observer.apply(ready)
                if all_stopped and horizon >= max(stopped.values()):
                    return
            news.clear()
            await news.wait()

    def tick(self) -> None:
        """Look at the wall clock again: called every ~50 ms while the world waits.

        By the held loop (virtual time, :class:`~._windows.Held`) or the world's own
        ticking (scaled): a worker that never answers ends the run all the same.
        """
        if self._news is not None:
            self._news.set()
        now = time.monotonic()
        if self._channel is not None and now - self._beaten >= BEAT_EVERY:
            self._beaten = now
            with contextlib.suppress(Exception):
                self._channel.send("all", Beat())

    async def _ticking(self) -> None:
        """Scaled time: :meth:`tick` every 50 ms of the loop's (real) time."""
        while True:
            await asyncio.sleep(0.05)
            self.tick()

    async def finish(self, *, hurry: bool = False) -> None:
        """The run ended: workers stop their robots; their last counts (``hurry``: briefly)."""
        channel = self._channel
        if channel is None:
            return
        with contextlib.suppress(Exception):
            channel.send("all", Stop())
        live = set(range(self._workers)) - self._byes
        if live and self._lost is None:
            with contextlib.suppress(WorkerLost):
                await self._until(
                    lambda: not (set(range(self._workers)) - self._byes - self._gone()),
                    HURRY_LIMIT if hurry else STOP_LIMIT,
                    "the workers' last counts",
                )

    def stats(self) -> dict[str, float | int | str]:
        """What the distribution cost: workers, windows, the longest wait of a worker.

        ``cross_process_effects`` (between workers' robots), wall seconds ``worker_waited_s``
        (others' windows and grants; ``_grant_s``: grants alone), ``world_observing_s``,
        ``window_busy_mean_s`` and ``window_busy_max_s`` (see :mod:`._window_costs`); on
        scaled time, ``late_effects`` and ``most_late_s`` (how far the workers fell behind).
        """
        virtual = self._scenario.run.virtual
        stats = self._costs.stats(self._workers, virtual=virtual)
        if not virtual:  # scaled time: what came late, and how late
            counts = self._counts.values()
            stats["late_effects"] = sum(c.late for c in counts)
            stats["most_late_s"] = max((c.most_late for c in counts), default=0.0)
        return stats

    def fault_counts(self) -> dict[str, int] | None:
        """The ``[faults]`` counts of every worker's robots, summed (``None``: no faults)."""
        return summed_faults(self._counts.values())

    def message_counts(self) -> tuple[dict[str, dict[str, int]], dict[str, int]]:
        """Every worker's message counts by kind and class, and drop reasons, summed.

        A lost worker's are its last report's. The control plane's refusals, the
        world's and the workers', are drops too (``control.*``), and so are the
        liveliness tokens no process of the run holds (``token.*``, see
        :mod:`._liveness`).
        """
        return summed_messages(
            self._counts.values(),
            {} if self._channel is None else self._channel.refused,
            {} if self._lobby is None else self._lobby.refused,
            self._liveness.tokens,
        )

    def abandon(self) -> None:
        """The run ends at once (a signal): the workers are told to stop, children killed."""
        if self._channel is not None:
            with contextlib.suppress(Exception):
                self._channel.send("all", Stop())
        self._children.kill()

    async def close(self, *, hurry: bool = False) -> None:
        """Closes the channels and the router; every child process is gone afterwards."""
        for closing in (self._channel, self._lobby):
            if closing is not None:
                closing.close()
        self._liveness.close()
        if self._token_of_world is not None:
            with contextlib.suppress(Exception):
                self._token_of_world.undeclare()
        await self._children.reap(hurry=hurry)
        for watcher in self._watchers:
            watcher.cancel()
        session, self._session = self._session, None
        if session is not None:
            session.close()

    # -- workers ---------------------------------------------------------------------

    def _joined(self, pid: int, index: int) -> None:
        self._pids[pid] = index

    def _exited(self, pid: int, code: int, said: str) -> None:
        """A child worker exited: a loss unless it said its Bye and exited cleanly."""
        index = self._pids.get(pid)
        if code == 0 and index is not None and index in self._byes:
            return
        setting_up = len(self._ready) < self._workers
        when = "during set-up" if setting_up else "during the run"
        who = "a worker" if index is None else f"worker {index}"
        # Exit code 2 is a worker's configuration error: the run cannot start on its host.
        lost = WorkerRefused if setting_up and code == 2 else WorkerLost
        robots = "" if index is None else lost_robots(self._shares, [index])
        said = f"its process {pid} exited with code {code} {when}: {said}{robots}"
        self._lose(lost(f"{who} is gone: {said}"))

    def _gone(self) -> set[int]:
        return {self._pids[pid] for pid in self._children.exited() if pid in self._pids}

    async def _until(self, condition: Callable[[], bool], seconds: float, what: str) -> None:
        """Waits until ``condition()`` holds, for at most ``seconds`` of wall time."""
        news = self._news
        assert news is not None
        began = time.monotonic()
        while not condition():
            if self._lost is not None:
                raise self._lost
            # A worker that joined and whose token went says something soon, or is gone.
            gone = self._liveness.silent(sorted(set(self._pids.values())), began)
            if gone:
                raise self._liveness.lost(gone, f" while the world waited for {what}")
            if time.monotonic() > began + seconds:
                raise WorkerLost(f"gave up after {seconds:g} s waiting for {what}")
            news.clear()
            await news.wait()  # news, or a tick

    def _lose(self, lost: BaseException) -> None:
        if self._lost is None:
            self._lost = lost
        if self._news is not None:
            self._news.set()

    # -- what comes in -----------------------------------------------------------------

    def _window(self, sender: int, window: Window) -> None:
        """A worker's window (virtual time): kept to observe, its costs counted."""
        self._latest[sender] = window
        if window.observation:
            self._pending.append(window.observation)
        self._costs.window(sender, window)
        latency, max_time = self._scenario.network.latency, self._scenario.run.max_time
        effects = (
            *(remote.at for remote in window.remote),
            *(motion.t + latency for motion in window.observation.motions),
        )
        latest = max((at for at in effects if at < max_time), default=-math.inf)
        self._effects_until = max(self._effects_until, latest)

    def _on_message(self, suffix: str, sender: int, message: Control) -> None:
        if not 0 <= sender < self._workers:
            raise ValueError(f"a message from no worker ({sender})")
        self._liveness.heard(sender)  # a signed word: it lives
        match message:
            case Window(k=k):
                if message.counts.internal or message.counts.external or message.counts.dropped:
                    self._counts[sender] = message.counts
                if k >= 0:
                    self._window(sender, message)
                else:  # scaled time: its robots' records so far, and where its time is
                    self._costs.flowed(message)
                    self._flowing.append(message.observation)
                    self._heard[sender] = max(self._heard.get(sender, 0.0), message.next_event)
                    if message.stopped_at is not None:
                        self._stopped_at[sender] = message.stopped_at
            case Ready():
                self._ready.add(sender)
            case Failed(error=error, configuration=True):
                self._lose(WorkerRefused(f"worker {sender} refused the run: {error}"))
            case Failed(error=error):
                self._lose(WorkerLost(f"worker {sender} failed: {error}"))
            case Bye(counts=counts, waited=waited, waited_grant=grant):
                self._counts[sender] = counts
                self._costs.waited(sender, waited, grant)
                self._costs.spread(sender, message.dependencies, message.watched)
                self._byes.add(sender)
                self._liveness.said_bye(sender)
        if self._news is not None:
            self._news.set()


def _all_stopped(windows: Iterable[Window]) -> float | None:
    """The instant the last robot stopped, once every worker's robots have; else ``None``."""
    instants = [window.stopped_at for window in windows]
    if any(at is None for at in instants):
        return None
    return max(at for at in instants if at is not None)


def _completed_at(observer: Observer) -> float:
    """The instant the observed records met the objective (met before any came: where it was)."""
    return observer.completed_at if observer.completed_at is not None else observer.until
