"""The world process of a run across processes: it shares the robots out, and observes them.

The **world** (plugged into :class:`~cas_async.scenario.ScenarioRun`) builds the
scenario like a run in one process (the mission: its robots, objective and
groups) but starts no robot. It runs a Zenoh router the workers connect to, deals
the robots out (:mod:`._partition`), starts the workers (``run --processes``) or
waits for them (``python -m cas_async world``), and observes: every window, every
worker's :class:`~._control.Window` goes to the run's
:class:`~._observer.Observer`, in the one order a run in one process applies them
too, and the world grants the next window, or stops the run.

Nothing else goes through the world: robots talk to robots, and hand items over,
worker to worker. A worker that exits, or goes quiet for ``run.window_limit``
wall seconds, ends the run as failed, naming it and its robots, and every run
leaves a ``results.json`` (the CLI writes it).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import secrets
import socket
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any, Final

from .._errors import ConfigurationError
from .._swarm_key import SwarmKey
from .._types import RobotId
from ..sim._environment import Environment
from ..transport._base import Transport
from ..transport._memory import MemoryTransport
from ..transport._zenoh import import_zenoh, loopback_config
from ._app import Mission
from ._control import (
    WORLD,
    Bye,
    Channel,
    Control,
    Counts,
    Failed,
    Full,
    Go,
    Grant,
    Hello,
    Ready,
    Stop,
    Welcome,
    Window,
)
from ._loader import Scenario
from ._observer import Observation, Observer
from ._partition import partition
from ._processes import WorkerLost, within
from ._results import RunStatus
from ._worker import LOBBY

__all__ = ["World"]

STOP_LIMIT: Final = 10.0
"""Wall seconds the world waits for its workers' last counts, all together."""
SUSPECT_LIMIT: Final = 2.0
"""Wall seconds a worker whose token went has to prove it lives (a signed message)."""
HELLO_AGE: Final = 30.0
"""Wall seconds a worker's hello stays fresh (an older one is a replay)."""
_STDERR_LINES: Final = 12


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
        self._lobby: Channel | None = None
        self._tokens: Any = None
        self._children: list[asyncio.subprocess.Process] = []
        self._stderr: dict[int, list[str]] = {}
        self._watchers: list[asyncio.Task[None]] = []
        self._joined: dict[str, int] = {}  # lobby nonce -> worker index
        self._ready: set[int] = set()
        self._counts: dict[int, Counts] = {}
        self._byes: set[int] = set()
        self._windows: dict[int, dict[int, Window]] = {}  # k -> worker -> its window
        self._flowing: list[Observation] = []  # scaled time: records not applied yet
        self._heard: dict[int, float] = {}  # scaled time: each worker's simulated time heard
        self._suspect: set[int] = set()  # workers whose token went: to prove they live
        self._lost: BaseException | None = None
        self._news: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._pids: dict[int, int] = {}  # a spawned worker's process id -> its index
        self._shares: list[list[RobotId]] = []
        self.rounds = 0
        """Windows closed so far (virtual time)."""
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
        ids = [robot.robot_id for robot in mission.robots]
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

    async def start(self) -> None:
        """Opens the router, starts (or awaits) the workers, and starts the run.

        Raises:
            ConfigurationError: the router cannot listen.
            WorkerLost: a worker exited or did not get ready within ``run.window_limit``.
        """
        self._news = asyncio.Event()
        self._loop = asyncio.get_running_loop()
        zenoh = import_zenoh()
        self.endpoint = _with_free_port(self._listen)
        config = loopback_config(mode="router", listen=[self.endpoint])
        try:
            self._session = await asyncio.to_thread(zenoh.open, config)
        except Exception as exc:
            raise ConfigurationError(f"world: cannot listen on {self.endpoint}: {exc}") from exc
        self._lobby = Channel(self._session, LOBBY, WORLD, self._key, self._on_lobby)
        self._lobby.listen("hello")
        self._channel = channel = Channel(
            self._session, self.namespace, WORLD, self._key, self._on_message
        )
        channel.listen("world")
        channel.listen("win/*")
        self._tokens = self._session.liveliness().declare_subscriber(
            f"{self.namespace}/worker/*",
            lambda sample: self._token(str(sample.key_expr), sample.kind),
        )
        if self._spawn:
            await self._spawn_workers()
        limit = self._scenario.run.window_limit
        await self._until(lambda: len(self._ready) >= self._workers, limit, "workers to be ready")
        epoch = time.time() + 0.5 if not self._scenario.run.virtual else 0.0
        channel.send("all", Go(epoch))

    async def coordinate(
        self, observer: Observer, done: Callable[[], bool], stop: asyncio.Event
    ) -> tuple[RunStatus, BaseException | None]:
        """Observes every window and grants the next, until the run ends (virtual time)."""
        scenario, channel = self._scenario, self._channel
        assert channel is not None
        latency, max_time = scenario.network.latency, scenario.run.max_time
        end, k = latency, 0
        while True:
            try:
                windows = await self._windows_of(k, stop)
            except WorkerLost as lost:
                return RunStatus.FAILED, lost
            if windows is None:
                return RunStatus.INTERRUPTED, None
            await observer.window(end, [windows[w].observation for w in sorted(windows)])
            self.rounds += 1
            if done():
                return RunStatus.COMPLETED, None
            next_event = min(
                (
                    t
                    for window in windows.values()
                    for t in (
                        window.next_event,
                        *(remote.at for remote in window.remote),
                        *(m.t + latency for m in window.observation.motions),
                    )
                ),
                default=math.inf,
            )
            if next_event >= max_time or math.isinf(next_event):
                await observer.sample_until(max_time, inclusive=False)
                return RunStatus.TIMED_OUT, None
            end = next_event + latency
            channel.send("all", Grant(k, end))
            k += 1

    async def follow(self, observer: Observer) -> None:
        """Applies what the workers report as it comes (scaled time); raises when one is lost.

        A record is applied once every worker has reported up to its instant, so
        that records come to the observer in order even from different workers.

        Raises:
            WorkerLost: a worker exited or failed.
        """
        news = self._news
        assert news is not None
        while True:
            if self._lost is not None:
                raise self._lost
            if len(self._heard) == self._workers and self._flowing:
                horizon = min(self._heard.values())
                ready, later = [], []
                for observation in self._flowing:
                    split = _split(observation, horizon)
                    ready.append(split[0])
                    if split[1]:
                        later.append(split[1])
                self._flowing = later
                observer.apply(ready)
            news.clear()
            await news.wait()

    async def _windows_of(self, k: int, stop: asyncio.Event) -> dict[int, Window] | None:
        """Every worker's window ``k`` (``None``: ``stop`` was set meanwhile)."""
        news = self._news
        assert news is not None
        limit = self._scenario.run.window_limit
        started = time.monotonic()
        while True:
            if self._lost is not None:
                raise self._lost
            got = self._windows.get(k, {})
            if len(got) >= self._workers:
                return self._windows.pop(k)
            if stop.is_set():
                return None
            missing = [w for w in range(self._workers) if w not in got]
            waited = time.monotonic() - started
            suspect = [w for w in missing if w in self._suspect]
            bound = SUSPECT_LIMIT if suspect else limit
            if waited > bound:
                who = suspect or missing
                raise WorkerLost(
                    f"window {k}: no word from worker{'s' if len(who) > 1 else ''} "
                    f"{', '.join(map(str, who))} within {bound:g} s: "
                    f"{'its process is gone' if suspect else 'frozen, or lost'}; "
                    f"its robots are lost: {self._robots_of(who)}"
                )
            news.clear()
            with contextlib.suppress(WorkerLost):
                await within(news.wait(), max(0.01, bound - waited), "news")

    async def finish(self) -> None:
        """The run ended: every worker stops its robots; their last counts, all at once."""
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
                    STOP_LIMIT,
                    "the workers' last counts",
                )

    def stats(self) -> dict[str, float | int | str]:
        """What the distribution cost: workers, windows, refusals on the control plane."""
        return {"workers": self._workers, "windows": self.rounds}

    def message_counts(self) -> tuple[dict[str, dict[str, int]], dict[str, int]]:
        """Every worker's message counts by kind and class, and drop reasons, summed.

        A lost worker's are its last report's. The control plane's refusals, the
        world's and the workers', are drops too (``control.*``).
        """
        total: dict[str, dict[str, int]] = {"internal": {}, "external": {}}
        dropped: dict[str, int] = {}
        reports = list(self._counts.values())
        for counts in reports:
            for kind, by_class in (("internal", counts.internal), ("external", counts.external)):
                for name, n in by_class.items():
                    total[kind][name] = total[kind].get(name, 0) + n
            for drops in (counts.dropped, counts.refused):
                for reason, n in drops.items():
                    dropped[reason] = dropped.get(reason, 0) + n
        for channel in (self._channel, self._lobby):
            if channel is not None:
                for reason, n in channel.refused.items():
                    dropped[reason] = dropped.get(reason, 0) + n
        return total, dropped

    async def close(self) -> None:
        """Closes the channels and the router; every child process is gone afterwards."""
        for channel in (self._channel, self._lobby):
            if channel is not None:
                channel.close()
        if self._tokens is not None:
            with contextlib.suppress(Exception):
                self._tokens.undeclare()
        await asyncio.gather(*(self._reap(child) for child in self._children))
        for watcher in self._watchers:
            watcher.cancel()
        session, self._session = self._session, None
        if session is not None:
            session.close()

    # -- workers ---------------------------------------------------------------------

    async def _spawn_workers(self) -> None:
        env = {**os.environ}
        if self._key is not None:
            env[SwarmKey.ENV_VAR] = self._key.secret.hex()
        for _ in range(self._workers):
            child = await asyncio.create_subprocess_exec(
                sys.executable,
                "-m",
                "cas_async",
                "worker",
                "--connect",
                self.endpoint,
                env=env,
                stdin=asyncio.subprocess.DEVNULL,
                stderr=asyncio.subprocess.PIPE,
            )
            self._children.append(child)
            self._watchers.append(asyncio.ensure_future(self._watch(child)))

    async def _watch(self, child: asyncio.subprocess.Process) -> None:
        """Passes a child's stderr on, keeps its last lines; its exit before its bye is a loss."""
        lines: list[str] = []
        assert child.stderr is not None
        async for raw in child.stderr:
            line = raw.decode(errors="replace")
            sys.stderr.write(line)
            lines.append(line.rstrip())
            del lines[:-_STDERR_LINES]
        code = await child.wait()
        index = self._pids.get(child.pid)
        if code == 0 and index is not None and index in self._byes:
            return
        said = "; ".join(line for line in lines[-3:] if line) or "nothing on stderr"
        when = "during set-up" if len(self._ready) < self._workers else "during the run"
        who = "a worker" if index is None else f"worker {index}"
        self._lose(
            WorkerLost(
                f"{who} (process {child.pid}) exited with code {code} {when}: {said}"
                + ("" if index is None else self._their_robots(index))
            )
        )

    async def _reap(self, child: asyncio.subprocess.Process) -> None:
        with contextlib.suppress(WorkerLost):
            await within(child.wait(), 5.0, "a worker to exit")
        if child.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                child.kill()
            await child.wait()

    def _gone(self) -> set[int]:
        return {
            self._pids[child.pid]
            for child in self._children
            if child.returncode is not None and child.pid in self._pids
        }

    async def _until(self, condition: Callable[[], bool], seconds: float, what: str) -> None:
        """Waits until ``condition()`` holds, for at most ``seconds`` of wall time."""
        news = self._news
        assert news is not None
        deadline = time.monotonic() + seconds
        while not condition():
            if self._lost is not None:
                raise self._lost
            left = deadline - time.monotonic()
            if left <= 0:
                raise WorkerLost(f"gave up after {seconds:g} s waiting for {what}")
            news.clear()
            with contextlib.suppress(WorkerLost):
                await within(news.wait(), left, what)

    def _lose(self, lost: BaseException) -> None:
        if self._lost is None:
            self._lost = lost
        if self._news is not None:
            self._news.set()

    def _robots_of(self, workers: Sequence[int]) -> str:
        ids = [robot for w in workers if w < len(self._shares) for robot in self._shares[w]]
        shown = ", ".join(str(i) for i in ids[:20])
        return shown + (f", ... ({len(ids) - 20} more)" if len(ids) > 20 else "")

    def _their_robots(self, index: int) -> str:
        if not self._shares:
            return ""
        robots = self._robots_of([index])
        return f"; worker {index}'s robots are lost: {robots}"

    # -- what comes in -----------------------------------------------------------------

    def _on_lobby(self, suffix: str, sender: int, message: Control) -> None:
        lobby = self._lobby
        match message:
            case Hello(nonce=nonce, sent=sent, pid=pid) if suffix == "hello" and lobby is not None:
                if abs(time.time() - sent) > HELLO_AGE:
                    raise ValueError("a stale hello (a replay?)")
                index = self._joined.get(nonce)
                if index is None and len(self._joined) < self._workers:
                    index = self._joined[nonce] = len(self._joined)
                    self._pids[pid] = index
                if index is None:
                    lobby.send(f"welcome/{nonce}", Full(self._workers))
                    return
                scenario = self._scenario
                lobby.send(
                    f"welcome/{nonce}",
                    Welcome(index, self.namespace, str(scenario.path), scenario.data, self.shares),
                )

    def _on_message(self, suffix: str, sender: int, message: Control) -> None:
        if not 0 <= sender < self._workers:
            raise ValueError(f"a message from no worker ({sender})")
        self._suspect.discard(sender)  # a signed word: it lives
        match message:
            case Window(k=k):
                if message.counts.internal or message.counts.external or message.counts.dropped:
                    self._counts[sender] = message.counts
                if k >= 0:
                    self._windows.setdefault(k, {})[sender] = message
                else:  # scaled time: its robots' records so far, and where its time is
                    self._flowing.append(message.observation)
                    self._heard[sender] = max(self._heard.get(sender, 0.0), message.next_event)
            case Ready():
                self._ready.add(sender)
            case Failed(error=error):
                self._lose(WorkerLost(f"worker {sender} failed: {error}"))
            case Bye(counts=counts):
                self._counts[sender] = counts
                self._byes.add(sender)
        if self._news is not None:
            self._news.set()

    def _token(self, key: str, kind: Any) -> None:
        """On a Zenoh thread: a worker's token went (a hint to check, never proof)."""
        loop = self._loop
        if loop is None or kind != import_zenoh().SampleKind.DELETE:
            return
        index = key.rsplit("/", 1)[1]
        if loop is not None and index.isdigit() and int(index) < self._workers:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(self._suspected, int(index))

    def _suspected(self, index: int) -> None:
        if index not in self._byes:
            self._suspect.add(index)
            if self._news is not None:
                self._news.set()


def _split(observation: Observation, horizon: float) -> tuple[Observation, Observation]:
    """The records of ``observation`` at or before ``horizon``, and the later ones."""
    return (
        Observation(
            [m for m in observation.motions if m.t <= horizon],
            [i for i in observation.items if i.t <= horizon],
        ),
        Observation(
            [m for m in observation.motions if m.t > horizon],
            [i for i in observation.items if i.t > horizon],
        ),
    )


def _with_free_port(endpoint: str) -> str:
    """``endpoint`` with port 0 replaced by one free now (Zenoh does not say which it bound)."""
    head, _, port = endpoint.rpartition(":")
    if port != "0":
        return endpoint
    _, _, host = head.partition("/")
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as probe:
        probe.bind((host.strip("[]"), 0))
        return f"{head}:{probe.getsockname()[1]}"
