"""A simulation across processes and hosts: one world process, N workers, on Zenoh.

The **world** (:class:`World`, plugged into :class:`~cas_async.scenario.ScenarioRun`)
builds the scenario like a single-process run, so it has the mission (target, groups,
measures) and an Environment with every robot, but starts no robot. It is the
authority for the Environment's items (one ledger: no item lost or held twice),
applies every motion the workers publish, samples the trace, shows progress, decides
when the run ends and writes the outputs, exactly as a single-process run does. It
runs a Zenoh router the workers connect to.

Each **worker** (:func:`run_worker`) joins through the router's lobby, receives the
scenario, runs the app's ``build()`` with the same seed (so every robot exists, at
the same pose, in every process) and starts only its share: robots ``k``, ``k + n``,
``k + 2n``... of the mission's list. Its Environment is a replica: each motion of
its own robots is published as its closed form (:meth:`Motion.to_numbers`), every
other process applies it, so poses and range queries stay local and exact. Item
operations go to the world and wait for its answer (:class:`ItemAuthority`).

Time: on virtual time every process runs a :class:`~._barrier.BarrierLoop`, and the
world grants each next instant (see :mod:`._barrier`); on scaled real time the world
hands out a wall-clock instant for simulated time 0, and no barrier is needed.

Lobby (``cas_async/lobby/ctl/...``): a worker says ``hello`` with a nonce until the
world answers ``welcome`` under that nonce, with its index, the run's namespace (a
random one per run) and the scenario. Everything is signed with the swarm key.

A worker that dies (its liveliness token goes) ends the run: the world names the
robots it lost and the result holds what was measured until then.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import os
import secrets
import socket
import sys
import threading
import time
import traceback
from collections.abc import Awaitable, Sequence
from pathlib import Path
from typing import Any, Final, TypeVar

from .._clock import Clock, ScaledClock
from .._errors import ConfigurationError, SimulationError, UnknownRobotError
from .._robot import Robot
from .._swarm import Swarm
from .._swarm_key import SwarmKey
from .._types import ItemId, RobotId
from ..sim._authority import ItemAuthority
from ..sim._environment import Environment
from ..sim._kinematics import Motion
from ..transport._authenticated import AuthenticatedTransport
from ..transport._base import Transport
from ..transport._memory import MemoryTransport
from ..transport._zenoh import ZenohTransport, import_zenoh, loopback_config
from ._app import Mission
from ._barrier import WORLD, BarrierLoop, Coordinator, Participant, Report
from ._link import Link
from ._loader import Scenario, scenario_from_data

__all__ = ["LOBBY", "World", "WorkerLost", "run_worker", "share_of"]

LOBBY: Final = "cas_async/lobby"
SETUP_LIMIT: Final = 60.0
"""Wall seconds the world waits for its workers to join and be ready."""
BYE_GRACE: Final = 1.0
"""Wall seconds a stopping worker's counts may arrive after its token went."""
STOP_LIMIT: Final = 10.0
"""Wall seconds the world waits for the workers' last counts."""

T = TypeVar("T")
_ERRORS: Final[dict[str, type[Exception]]] = {
    "SimulationError": SimulationError,
    "UnknownRobotError": UnknownRobotError,
}


class WorkerLost(ConfigurationError):
    """A worker process went away or failed during the run."""


def share_of(robots: Sequence[Robot], index: int, workers: int) -> list[Robot]:
    """The robots worker ``index`` of ``workers`` runs: every ``workers``-th from ``index``."""
    return list(robots[index::workers])


async def bounded(aw: Awaitable[T], seconds: float, what: str) -> T:
    """Awaits ``aw`` for at most ``seconds`` of wall time, even while virtual time stands still.

    ``asyncio.timeout`` counts loop time, which does not pass on a barrier loop
    before the run starts: a thread's timer cancels the wait instead.

    Raises:
        WorkerLost: the time ran out, naming ``what`` was awaited.
    """
    task = asyncio.ensure_future(aw)
    loop = asyncio.get_running_loop()
    expired = threading.Event()

    def expire() -> None:
        expired.set()
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(task.cancel)

    timer = threading.Timer(seconds, expire)
    timer.daemon = True
    timer.start()
    try:
        return await task
    except asyncio.CancelledError:
        if expired.is_set():
            raise WorkerLost(f"gave up after {seconds:g} s waiting for {what}") from None
        raise
    finally:
        timer.cancel()
        if not task.done():
            task.cancel()


class _Counts:
    """Messages between processes, as the barrier counts them."""

    __slots__ = ("received", "sent")

    def __init__(self) -> None:
        self.sent = 0
        self.received = 0


# -- the world ------------------------------------------------------------------------


class World:
    """The world process's side of a run across processes (see the module docs).

    Args:
        scenario: the loaded scenario.
        workers: how many worker processes run the robots.
        key: the swarm key; a random one is made for workers spawned here.
        listen: the Zenoh endpoint the world's router listens on.
        spawn: start the workers here as child processes (``--processes``), or
            wait for workers started elsewhere (``python -m cas_async world``).
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
        self._counts = _Counts()
        self._session: Any = None
        self._link: Link | None = None
        self._lobby: Link | None = None
        self._tokens: Any = None
        self._alive: Any = None  # the world's token: workers stop when it goes
        self._children: list[asyncio.subprocess.Process] = []
        self._joined: dict[str, int] = {}  # lobby nonce -> worker index
        self._ready: set[int] = set()
        self._byes: dict[int, list[Any]] = {}
        self._gone: set[int] = set()
        self._done = False
        self._setup: asyncio.Future[None] | None = None
        self._lost: asyncio.Future[None] | None = None
        self._stopped: asyncio.Future[None] | None = None
        self._environment: Environment | None = None
        self._shares: list[list[RobotId]] = []
        self._coordinator: Coordinator | None = None
        self.participant: Participant | None = None
        self._scenario_clock: ScaledClock | None = None
        self.endpoint = ""
        """Where the router listens, once started."""

    # -- what ScenarioRun asks -------------------------------------------------------

    def transport(self) -> Transport:
        """What the world's own copies of the robots are built with: they never start."""
        return MemoryTransport()

    def adopt(self, environment: Environment, mission: Mission) -> None:
        """Takes the built mission: the world keeps its Environment, the workers its robots."""
        self._environment = environment
        ids = [robot.robot_id for robot in mission.robots]
        self._shares = [ids[k :: self._workers] for k in range(self._workers)]

    @property
    def rounds(self) -> int:
        """Time grants so far (virtual time), the barrier's rounds."""
        return 0 if self._coordinator is None else self._coordinator.rounds

    async def start(self) -> None:
        """Opens the router, starts (or awaits) the workers, and starts the clock for all."""
        loop = asyncio.get_running_loop()
        self._setup = loop.create_future()
        self._lost = loop.create_future()
        self._stopped = loop.create_future()
        zenoh = import_zenoh()
        self.endpoint = _with_free_port(self._listen)
        config = loopback_config(mode="router", listen=[self.endpoint])
        try:
            self._session = await asyncio.to_thread(zenoh.open, config)
        except Exception as exc:
            raise ConfigurationError(f"world: cannot listen on {self.endpoint}: {exc}") from exc
        self._lobby = Link(self._session, LOBBY, self._key, self._on_lobby)
        self._lobby.listen("hello")
        self._link = link = Link(self._session, self.namespace, self._key, self._on_message)
        link.listen("world")
        link.listen("motion")
        self._alive = self._session.liveliness().declare_token(f"{self.namespace}/world")
        self._tokens = self._session.liveliness().declare_subscriber(
            f"{self.namespace}/worker/*",
            lambda sample: self._worker_token(str(sample.key_expr), sample.kind),
        )
        if self._spawn:
            await self._spawn_workers()
        await bounded(self._setup, SETUP_LIMIT, f"{self._workers} workers to be ready")
        epoch = time.time() + 0.2  # every process hears it before it comes
        if self._scenario.run.virtual:
            coordinator = self._coordinator = Coordinator(
                self._workers,
                lambda ticket: link.send("all", ["prepare", ticket]),
                lambda round_, until: link.send("all", ["grant", round_, until]),
            )
            participant = Participant(WORLD, self._count, coordinator.report)
            coordinator.world = self.participant = participant
            link.send("all", ["go", 0.0])
            running = loop
            if isinstance(running, BarrierLoop):
                running.activate(participant)
        else:
            clock = self._scenario_clock
            link.send("all", ["go", epoch])
            if clock is not None:
                clock.start_at_wall(epoch)

    def use_clock(self, clock: Clock) -> None:
        """The run's clock: a scaled one is aligned with the workers' at the start."""
        if isinstance(clock, ScaledClock):
            self._scenario_clock = clock

    async def _spawn_workers(self) -> None:
        env = {**os.environ}
        if self._key is not None:
            env[SwarmKey.ENV_VAR] = self._key.secret.hex()
        for _ in range(self._workers):
            self._children.append(
                await asyncio.create_subprocess_exec(
                    sys.executable,
                    "-m",
                    "cas_async",
                    "worker",
                    "--connect",
                    self.endpoint,
                    env=env,
                    stdin=asyncio.subprocess.DEVNULL,
                )
            )

    async def running(self) -> None:
        """Waits until a worker is lost or fails: raises :class:`WorkerLost` naming its robots."""
        if self._lost is None:
            raise ConfigurationError("world: start() it before running()")
        await self._lost

    async def finish(self) -> None:
        """The run ended: stops every worker's robots and waits for their last counts."""
        if self._link is None or self._stopped is None or self._done:
            return
        self._done = True
        self._link.send("all", ["stop"])
        if len(self._byes) + len(self._gone) < self._workers:
            with contextlib.suppress(WorkerLost, asyncio.CancelledError):
                await bounded(self._stopped, STOP_LIMIT, "the workers' last counts")

    def stats(self) -> dict[str, float | int | str]:
        """What the distribution cost: workers, barrier rounds, messages between processes."""
        stats: dict[str, float | int | str] = {"workers": self._workers}
        if self._coordinator is not None:
            stats["barrier rounds"] = self._coordinator.rounds
            stats["barrier rounds redone"] = self._coordinator.aborted
        stats["world messages"] = self._counts.sent + self._counts.received
        return stats

    def message_counts(self) -> tuple[dict[str, dict[str, int]], dict[str, int]]:
        """Every worker's message counts by kind and class, and drop reasons, summed."""
        total: dict[str, dict[str, int]] = {"internal": {}, "external": {}}
        dropped: dict[str, int] = {}
        for internal, external, drops in self._byes.values():
            for kind, counts in (("internal", internal), ("external", external)):
                for name, n in counts.items():
                    total[kind][name] = total[kind].get(name, 0) + n
            for reason, n in drops.items():
                dropped[reason] = dropped.get(reason, 0) + n
        return total, dropped

    async def close(self) -> None:
        """Closes the channel and the router; every child process is gone afterwards."""
        self._done = True
        if self._link is not None:
            with contextlib.suppress(Exception):  # ended early (a lost worker): the rest stop too
                self._link.send("all", ["stop"])
        for link in (self._link, self._lobby):
            if link is not None:
                link.close()
        for declared in (self._tokens, self._alive):
            if declared is not None:
                with contextlib.suppress(Exception):
                    declared.undeclare()
        for child in self._children:
            with contextlib.suppress(ProcessLookupError, WorkerLost):
                await bounded(child.wait(), 5.0, "a worker to exit")
            if child.returncode is None:
                with contextlib.suppress(ProcessLookupError):
                    child.kill()
                await child.wait()
        session, self._session = self._session, None
        if session is not None:
            session.close()

    # -- what arrives ----------------------------------------------------------------

    def _count(self) -> tuple[int, int]:
        return self._counts.sent, self._counts.received

    def _on_lobby(self, suffix: str, message: list[Any]) -> None:
        match message:
            case ["hello", str(nonce)] if suffix == "hello":
                index = self._joined.get(nonce)
                if index is None and len(self._joined) < self._workers:
                    index = self._joined[nonce] = len(self._joined)
                lobby = self._lobby
                if lobby is None:
                    return
                if index is None:
                    lobby.send(f"welcome/{nonce}", ["full", self._workers])
                    return
                scenario = self._scenario
                lobby.send(
                    f"welcome/{nonce}",
                    [
                        "welcome",
                        index,
                        self._workers,
                        self.namespace,
                        str(scenario.path),
                        scenario.data,
                    ],
                )

    def _on_message(self, suffix: str, message: list[Any]) -> None:
        match message:
            case ["motion", int(worker), int(robot), float(t), list(numbers)]:
                if worker != WORLD:
                    self._counts.received += 1
                    self._apply_motion(robot, t, numbers)
            case ["item", int(worker), int(request), str(op), list(args)]:
                self._counts.received += 1
                self._serve_item(worker, request, op, args)
            case ["ready", int(worker)]:
                self._ready.add(worker)
                if len(self._ready) == self._workers and self._setup and not self._setup.done():
                    self._setup.set_result(None)
            case ["idle", int(worker), int(round_), deadline, int(sent), int(received)]:
                if self._coordinator is not None:
                    self._coordinator.report(
                        worker, Report(round_, float(deadline), sent, received)
                    )
            case ["confirm", int(worker), int(ticket), bool(unchanged)]:
                if self._coordinator is not None:
                    self._coordinator.confirmed(worker, ticket, unchanged)
            case ["failed", int(worker), str(error)]:
                self._fail(f"worker {worker} failed: {error}")
            case ["bye", int(worker), dict(internal), dict(external), dict(dropped)]:
                self._byes[worker] = [internal, external, dropped]
                self._gone.add(worker)
                self._check_stopped()

    def _check_stopped(self) -> None:
        stopped = self._stopped
        if stopped is not None and not stopped.done() and len(self._gone) >= self._workers:
            stopped.set_result(None)

    def _apply_motion(self, robot: RobotId, t: float, numbers: list[Any]) -> None:
        if self._environment is None:
            return
        try:
            self._environment.start_motion(robot, Motion.from_numbers(numbers), t)
        except (SimulationError, UnknownRobotError) as exc:
            self._fail(f"robot {robot}: a motion the world cannot apply: {exc}")

    def _serve_item(self, worker: int, request: int, op: str, args: list[Any]) -> None:
        environment, link = self._environment, self._link
        if environment is None or link is None:
            return
        try:
            match op, args:
                case "create_item", [int(robot), float(t)]:
                    value: Any = environment.create_item(robot, t)
                case "hand_over", [int(item), int(giver), int(receiver), float(t), float(reach)]:
                    environment.hand_over(item, giver, receiver, t, reach=reach)
                    value = None
                case "retire_item", [int(item), int(robot), float(t)]:
                    environment.retire_item(item, robot, t)
                    value = None
                case "accept_from", [int(receiver), int(giver)]:
                    environment.accept_from(receiver, giver)
                    value = None
                case "refuse_from", [int(receiver), int(giver)]:
                    environment.refuse_from(receiver, giver)
                    value = None
                case "held_by", [int(robot)]:
                    value = list(environment.items.held_by(robot))
                case _:
                    raise SimulationError(f"no item operation {op}{tuple(args)}")
            reply = ["reply", request, True, value]
        except (SimulationError, UnknownRobotError) as exc:
            reply = ["reply", request, False, [type(exc).__name__, str(exc)]]
        link.send(f"w/{worker}", reply)
        self._counts.sent += 1

    def _worker_token(self, key: str, kind: Any) -> None:
        """On a Zenoh thread: a worker's token came or went."""
        loop = self._lost.get_loop() if self._lost is not None else None
        if loop is None or kind != import_zenoh().SampleKind.DELETE:
            return
        worker = int(key.rsplit("/", 1)[1])
        with contextlib.suppress(RuntimeError):
            loop.call_soon_threadsafe(self._worker_gone, worker)

    def _worker_gone(self, worker: int, *, waited: bool = False) -> None:
        if worker in self._gone:
            return
        if self._done and not waited:
            # Stopping: its token may go before its last counts arrive (two
            # subscriptions, in no order): give the 'bye' a moment of wall time.
            later = functools.partial(self._worker_gone, worker, waited=True)
            timer = threading.Timer(BYE_GRACE, _call_soon, (asyncio.get_running_loop(), later))
            timer.daemon = True
            timer.start()
            return
        self._gone.add(worker)
        self._check_stopped()
        if self._done:
            return
        lost = self._shares[worker] if worker < len(self._shares) else []
        self._fail(
            f"worker {worker} is gone (its process ended or lost its connection); "
            f"its {len(lost)} robots are lost: {_ids(lost)}"
        )

    def _fail(self, error: str) -> None:
        for future in (self._lost, self._setup):
            if future is not None and not future.done():
                future.set_exception(WorkerLost(error))


def _call_soon(loop: asyncio.AbstractEventLoop, callback: Any) -> None:
    """From another thread: ``callback`` on ``loop``, unless the loop has closed."""
    with contextlib.suppress(RuntimeError):
        loop.call_soon_threadsafe(callback)


def _with_free_port(endpoint: str) -> str:
    """``endpoint`` with port 0 replaced by one free now (Zenoh does not say which it bound)."""
    head, _, port = endpoint.rpartition(":")
    if port != "0":
        return endpoint
    _, _, host = head.partition("/")
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as probe:
        probe.bind((host.strip("[]"), 0))
        return f"{head}:{probe.getsockname()[1]}"


def _ids(ids: Sequence[int], limit: int = 20) -> str:
    shown = ", ".join(str(i) for i in ids[:limit])
    return shown + (f", ... ({len(ids) - limit} more)" if len(ids) > limit else "")


# -- a worker -------------------------------------------------------------------------


class _RemoteItems(ItemAuthority):
    """Item operations decided by the world: each a request and its reply."""

    def __init__(self, link: Link, worker: int, counts: _Counts) -> None:
        self._link = link
        self._worker = worker
        self._counts = counts
        self._next = 0
        self._waiting: dict[int, asyncio.Future[Any]] = {}

    async def _ask(self, op: str, *args: Any) -> Any:
        self._next += 1
        request = self._next
        future: asyncio.Future[Any] = asyncio.get_running_loop().create_future()
        self._waiting[request] = future
        self._link.send("world", ["item", self._worker, request, op, list(args)])
        self._counts.sent += 1
        try:
            return await future
        finally:
            self._waiting.pop(request, None)

    def answered(self, request: int, ok: bool, value: Any) -> None:
        """The world's reply to request ``request``."""
        self._counts.received += 1
        future = self._waiting.get(request)
        if future is None or future.done():
            return
        if ok:
            future.set_result(value)
        else:
            kind, text = value
            future.set_exception(_ERRORS.get(kind, SimulationError)(text))

    async def create_item(self, robot_id: RobotId, t: float) -> ItemId:
        return int(await self._ask("create_item", robot_id, float(t)))

    async def hand_over(
        self, item: ItemId, giver: RobotId, receiver: RobotId, t: float, *, reach: float
    ) -> None:
        await self._ask("hand_over", item, giver, receiver, float(t), float(reach))

    async def retire_item(self, item: ItemId, robot_id: RobotId, t: float) -> None:
        await self._ask("retire_item", item, robot_id, float(t))

    async def accept_from(self, receiver: RobotId, giver: RobotId) -> None:
        await self._ask("accept_from", receiver, giver)

    async def refuse_from(self, receiver: RobotId, giver: RobotId) -> None:
        await self._ask("refuse_from", receiver, giver)

    async def held_by(self, robot_id: RobotId) -> tuple[ItemId, ...]:
        return tuple(await self._ask("held_by", robot_id))


async def _welcome(connect: str, key: SwarmKey | None) -> list[Any]:
    """Joins through the world's lobby; returns its ``welcome``."""
    zenoh = import_zenoh()
    config = loopback_config(mode="client", listen=[], connect=[connect])
    try:
        session = await asyncio.to_thread(zenoh.open, config)
    except Exception as exc:
        raise ConfigurationError(f"worker: cannot connect to {connect}: {exc}") from exc
    nonce = secrets.token_hex(8)
    answer: asyncio.Future[list[Any]] = asyncio.get_running_loop().create_future()

    def handle(suffix: str, message: list[Any]) -> None:
        if suffix == f"welcome/{nonce}" and not answer.done():
            answer.set_result(message)

    lobby = Link(session, LOBBY, key, handle)
    try:
        lobby.listen(f"welcome/{nonce}")
        deadline = time.monotonic() + SETUP_LIMIT
        while not answer.done():
            if time.monotonic() > deadline:
                raise WorkerLost(f"worker: no answer from a world at {connect} (wrong key?)")
            lobby.send("hello", ["hello", nonce])
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(asyncio.shield(answer), 0.25)
        return answer.result()
    finally:
        lobby.close()
        session.close()


def run_worker(connect: str, key: SwarmKey | None, *, listen: Sequence[str] = ()) -> int:
    """A worker process from start to end: joins the world at ``connect``, runs its share.

    Returns the exit code: 0 when the world stopped the run, 1 when this worker failed.

    Raises:
        ConfigurationError: the world cannot be reached, or refused this worker.
    """
    welcome = asyncio.run(_welcome(connect, key))
    match welcome:
        case ["welcome", int(index), int(workers), str(namespace), str(path), dict(data)]:
            pass
        case ["full", int(workers)]:
            raise ConfigurationError(f"worker: the world at {connect} has its {workers} workers")
        case _:
            raise ConfigurationError(f"worker: the world at {connect} answered {welcome!r}")
    scenario = scenario_from_data(Path(path), data)
    worker = _Worker(scenario, index, workers, namespace, connect, key, listen)
    if scenario.run.virtual:
        with asyncio.Runner(loop_factory=BarrierLoop) as runner:
            return runner.run(worker.run())
    from .._runner import run

    return run(worker.run())


class _Worker:
    def __init__(
        self,
        scenario: Scenario,
        index: int,
        workers: int,
        namespace: str,
        connect: str,
        key: SwarmKey | None,
        listen: Sequence[str],
    ) -> None:
        self._scenario = scenario
        self._index = index
        self._workers = workers
        self._counts = _Counts()
        self._zenoh = ZenohTransport(
            namespace=namespace,
            mode="peer" if listen else "client",
            listen=listen,
            connect=[connect],
            shared_virtual_time=scenario.run.virtual,
        )
        self._transport: Transport = (
            self._zenoh if key is None else AuthenticatedTransport(self._zenoh, key)
        )
        self._key = key
        self._namespace = namespace
        self._go: asyncio.Future[float] | None = None
        self._stop: asyncio.Future[None] | None = None
        self._items: _RemoteItems | None = None
        self._environment = Environment()
        self._own: set[RobotId] = set()
        self._participant: Participant | None = None
        self._world_lost = False

    def _count(self) -> tuple[int, int]:
        return self._counts.sent + self._zenoh.sent, self._counts.received + self._zenoh.received

    async def run(self) -> int:
        loop = asyncio.get_running_loop()
        self._go, self._stop = loop.create_future(), loop.create_future()
        scenario = self._scenario
        clock = scenario.clock()
        mission = scenario.app.build(scenario.setup(self._environment, clock, self._transport))
        share = share_of(mission.robots, self._index, self._workers)
        self._own = {robot.robot_id for robot in share}
        await self._zenoh.start()
        link = self._link = Link(self._zenoh.session, self._namespace, self._key, self._on_message)
        token = world_watch = None
        swarm = Swarm(share)
        failed: str | None = None
        try:
            link.listen("all")
            link.listen(f"w/{self._index}")
            link.listen("motion")
            self._items = _RemoteItems(link, self._index, self._counts)
            self._environment.item_authority = self._items
            self._environment.watch_motions(self._publish_motion)
            token = self._zenoh.session.liveliness().declare_token(
                f"{self._namespace}/worker/{self._index}"
            )
            world_watch = self._zenoh.session.liveliness().declare_subscriber(
                f"{self._namespace}/world",
                functools.partial(self._world_token, loop),
                history=True,
            )
            await swarm.open()
            everyone = [robot.robot_id for robot in mission.robots]
            await bounded(self._zenoh.wait_for(everyone), SETUP_LIMIT, "every robot to join")
            link.send("world", ["ready", self._index])
            epoch = await bounded(self._go, SETUP_LIMIT, "the world's go")
            if isinstance(clock, ScaledClock):
                clock.start_at_wall(epoch)
            elif isinstance(loop, BarrierLoop):
                self._participant = participant = Participant(
                    self._index, self._count, self._report
                )
                loop.activate(participant)
            swarm.start()
            running = asyncio.ensure_future(swarm.run())
            await asyncio.wait((running, self._stop), return_when=asyncio.FIRST_COMPLETED)
            if running.done() and not running.cancelled() and running.exception() is not None:
                failed = str(running.exception())
            running.cancel()
            with contextlib.suppress(BaseException):
                await running
        except Exception as exc:
            failed = f"{type(exc).__name__}: {exc}"
            traceback.print_exc()
        finally:
            if self._participant is not None:
                self._participant.over = True  # stopping takes no simulated time
            with contextlib.suppress(Exception):
                await swarm.__aexit__(None, None, None)
            if failed is not None:
                link.send("world", ["failed", self._index, failed])
            counts = swarm.message_counts()
            link.send(
                "world",
                ["bye", self._index, counts["internal"], counts["external"], swarm.drop_counts()],
            )
            for declared in (token, world_watch):
                if declared is not None:
                    with contextlib.suppress(Exception):
                        declared.undeclare()
            link.close()
            self._zenoh.close()
        if failed is None and self._world_lost:
            failed = "the world is gone"
        if failed is not None:
            print(f"worker {self._index}: {failed}", file=sys.stderr)
        return 1 if failed is not None else 0

    def _world_token(self, loop: asyncio.AbstractEventLoop, sample: Any) -> None:
        """On a Zenoh thread: the world's token went: its run is over, this worker stops."""
        if sample.kind == import_zenoh().SampleKind.DELETE:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(self._world_gone)

    def _world_gone(self) -> None:
        self._world_lost = True
        if self._stop is not None and not self._stop.done():
            self._stop.set_result(None)
        if self._go is not None and not self._go.done():
            self._go.set_exception(WorkerLost("the world is gone before the run started"))

    def _report(self, ident: int, report: Report) -> None:
        self._link.send(
            "world",
            ["idle", ident, report.round, report.deadline, report.sent, report.received],
        )

    def _publish_motion(self, robot: RobotId, motion: Motion, start: float) -> None:
        if robot in self._own:
            self._link.send(
                "motion", ["motion", self._index, robot, float(start), motion.to_numbers()]
            )
            self._counts.sent += self._workers  # the world and every other worker

    def _on_message(self, suffix: str, message: list[Any]) -> None:
        match message:
            case ["motion", int(worker), int(robot), float(t), list(numbers)]:
                if worker != self._index:
                    self._counts.received += 1
                    self._environment.start_motion(robot, Motion.from_numbers(numbers), t)
            case ["reply", int(request), bool(ok), value]:
                if self._items is not None:
                    self._items.answered(request, ok, value)
            case ["go", float(epoch)]:
                if self._go is not None and not self._go.done():
                    self._go.set_result(epoch)
            case ["prepare", int(ticket)]:
                participant = self._participant
                if participant is not None:
                    self._link.send(
                        "world", ["confirm", self._index, ticket, participant.unchanged()]
                    )
            case ["grant", int(round_), until]:
                if self._participant is not None:
                    self._participant.granted(round_, float(until))
            case ["stop"]:
                if self._stop is not None and not self._stop.done():
                    self._stop.set_result(None)
