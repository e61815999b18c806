"""A worker process of a run across processes: its share of the robots, window by window.

``python -m cas_async worker --connect ENDPOINT`` (or a child of ``run --processes``)
joins the world (:mod:`._joining`), builds the scenario the world sends (every
robot, with the run's seed: the application draws the same numbers in every
process) and starts its share. Its robots talk through a
:class:`~._network.ProcessNetwork`; on virtual time its loop moves in windows
(:mod:`._windows`): when every event before a window's end has run, the worker
publishes its :class:`~._control.Window`, with its promise, and its next window
ends where the promises of the workers it depends on, its step of ``run.credit``
and the world's :class:`~._control.Grant` let it (see :mod:`._control`). On scaled time it
publishes what its robots did as it goes, from simulated time 0 on, which is the
wall-clock instant the world's :class:`~._control.Go` names.

A worker stops by itself when its world is gone: the world beats every
:data:`~._control.BEAT_EVERY`; when its liveliness token goes (a hint, not proof)
it has :data:`~._control.SUSPECT_LIMIT` to say something, and any silence longer
than ``run.window_limit`` ends the worker all the same. A token of the world's
that goes while the world's still answers is a stranger's: counted
(``token.forged``, in the counts it reports), and nothing more.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import sys
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any, Final

from ..._core._gc_policy import young_generation_for
from ..._core._swarm import Swarm
from ..._core._transport_contract import Transport
from ..._errors import ConfigurationError
from ..._time._clock import Clock, ScaledClock
from ..._time._deliveries import Deliveries
from ..._time._loop_factory import run
from ..._time._virtual_loop import VirtualTimeLoop
from ..._wire._swarm_key import SwarmKey
from ...transport._faulty import FaultyTransport
from ...transport.zenoh import import_zenoh, loopback_config
from .._spec._layers import check_built
from .._spec._loader import Scenario, scenario_from_data
from .._spec._run_transport import faulty, ranged
from ._control import (
    SUSPECT_LIMIT,
    WORLD,
    Bye,
    Channel,
    Control,
    Counts,
    Failed,
    Go,
    Grant,
    Ready,
    Stop,
    Welcome,
    Window,
    token_lives,
)
from ._halo import Halo
from ._joining import CONNECT_WAIT, join, refuse
from ._lost import WorkerLost, within
from ._network import ProcessNetwork
from ._observer import Recorder
from ._windows import Held, Steps, Windows

__all__ = ["run_worker"]

HEARTBEAT: Final = 0.05
"""Wall seconds between two reports of a worker's simulated time, on scaled time."""
COUNTS_EVERY: Final = 1.0
"""Wall seconds between two counts a worker reports (the last ones come with its ``Bye``)."""


def run_worker(
    connect: str,
    key: SwarmKey | None,
    *,
    listen: Sequence[str] = (),
    quiet: bool = False,
    wait: float = CONNECT_WAIT,
) -> int:
    """A worker process from start to end: joins the world at ``connect``, runs its share.

    Says on stderr which worker it is and which robots it runs, unless ``quiet``
    (a worker the world started itself). Returns the exit code: 0 when the world
    stopped the run, 1 when this worker failed. ``wait``: wall seconds to wait for
    the world to listen at ``connect`` (see :func:`~._joining.connected`).

    Raises:
        ConfigurationError: the world cannot be reached, or refused this worker.
        WorkerLost: the world did not answer.
    """
    welcome = asyncio.run(join(connect, key, 60.0, wait))
    try:
        scenario = scenario_from_data(Path(welcome.path), welcome.data)
    except ConfigurationError as exc:  # its app cannot be imported here, say
        asyncio.run(refuse(connect, key, welcome, str(exc)))
        raise
    if not quiet:
        share = welcome.shares[welcome.index]
        print(
            f"worker {welcome.index} of {len(welcome.shares)}: its {len(share)} robots: "
            + ", ".join(map(str, share)),
            file=sys.stderr,
        )
    worker = _Worker(scenario, welcome, connect, key, tuple(listen))
    # As in a run in one process, the collector's youngest generation is sized to the
    # robots built here while they run: its share (see _gc_policy). Without it a worker
    # of scale_2500 holding all the robots took 47 CPU s, not 38.
    try:
        with young_generation_for(len(welcome.shares[welcome.index])):
            if scenario.run.virtual:
                with asyncio.Runner(loop_factory=VirtualTimeLoop) as runner:
                    return runner.run(worker.run())
            return run(worker.run())
    except ConfigurationError as exc:  # the app could not build its robots here
        asyncio.run(refuse(connect, key, welcome, str(exc)))
        raise


class _Worker:
    def __init__(
        self,
        scenario: Scenario,
        welcome: Welcome,
        connect: str,
        key: SwarmKey | None,
        listen: tuple[str, ...],
    ) -> None:
        self._scenario = scenario
        self._welcome = welcome
        self._index = welcome.index
        self._connect = connect
        self._key = key
        self._listen = listen
        self._k = 0
        # What the others promised (see _bounds): nothing happens before time 0.
        latency = scenario.network.latency
        others = (w for w in range(len(welcome.shares)) if w != welcome.index)
        self._promised: dict[int, float] = dict.fromkeys(others, latency)
        self._cells: dict[int, dict[int, list[int]]] = {}  # epoch -> worker -> cells at start
        # The steps the world let run: no run ends before the end of step 2 (see Steps).
        self._granted = 2
        self._steps = Steps(1.0, 0.0, 0.0)  # where windows end: set when the run starts
        self._counted = time.monotonic()  # when the counts were last reported (scaled time)
        self._counted_at = time.perf_counter()  # virtual time: when they were last taken
        self._counts_due = Counts()  # virtual time: taken, to go with the next window
        self._stop: asyncio.Event | None = None
        self._news: asyncio.Event | None = None  # something came in: look again
        self._go: asyncio.Future[float] | None = None
        self._channel: Channel | None = None
        self._network: ProcessNetwork | None = None
        self._recorder: Recorder | None = None
        self._swarm = Swarm(())
        self._flushing = False
        self._stopped_at: float | None = None  # when every robot here had stopped
        self._halo: Halo | None = None  # with an interaction range: what it watches
        self._depended = 0.0  # summed over windows: workers depended on
        self._watched = 0.0  # summed over windows: the others' robots watched
        self._clock: Clock | None = None
        self._final: Counts | None = None  # the counts as the run ended (virtual time)
        self._waited = 0.0  # wall seconds waiting for the others and for grants
        self._waited_grant = 0.0  # the part of it with every other window in: for a grant
        self._resumed = 0.0  # when the window running could start (perf_counter)
        self._world_word = time.monotonic()  # when the world last said something
        self._world_suspect = False  # its token went: it has SUSPECT_LIMIT to say something
        self._world_lost: str | None = None
        self._session: Any = None
        self._wire: Transport | None = None  # the robots' transport: the network, faulty or not
        self._watching: list[asyncio.Future[None]] = []  # token checks under way
        self._forged = 0  # the world's token went while it still answered: a stranger's

    async def run(self) -> int:
        loop = asyncio.get_running_loop()
        self._stop, self._news = asyncio.Event(), asyncio.Event()
        self._go = loop.create_future()
        scenario, welcome = self._scenario, self._welcome
        clock = self._clock = scenario.clock()
        environment = scenario.environment(clock)
        owners = {robot: worker for worker, share in enumerate(welcome.shares) for robot in share}
        own = set(welcome.shares[self._index])
        virtual = scenario.run.virtual
        network = self._network = ProcessNetwork(
            owners,
            self._index,
            scenario.network.latency,
            clock,
            environment,
            flush=None if virtual else self._schedule_flush,
        )
        self._wire = faulty(scenario, network, clock)
        transport = ranged(self._wire, environment, clock)
        mission = scenario.app.build(scenario.setup(environment, clock, transport, frozenset(own)))
        mine = [robot for robot in mission.robots if robot.robot_id in own]  # holds(), or not
        check_built(getattr(scenario.app, "stack", ()), scenario.layers, mine)
        environment.set_local(own, network)
        limit, latency = environment.interaction_range, scenario.network.latency
        if virtual and limit is not None:  # watch only the others' robots near its own
            self._halo = Halo(environment, owners, self._index, limit, latency, scenario.credit)
            network.watch(self._halo.visible)
        per_epoch = 0 if self._halo is None else self._halo.steps
        self._steps = Steps(scenario.credit, latency, scenario.run.max_time, per_epoch)
        self._recorder = Recorder(environment, own)
        self._swarm = swarm = Swarm(mine)
        zenoh = import_zenoh()
        config = loopback_config(
            mode="peer" if self._listen else "client",
            listen=list(self._listen),
            connect=[self._connect],
        )
        session = self._session = await asyncio.to_thread(zenoh.open, config)
        channel = self._channel = Channel(
            session, welcome.namespace, self._index, self._key, self._on_message
        )
        failed: str | None = None
        token = world_watch = None
        try:
            channel.listen("all")
            channel.listen("win/*")
            token = session.liveliness().declare_token(f"{welcome.namespace}/worker/{self._index}")
            world_watch = session.liveliness().declare_subscriber(
                f"{welcome.namespace}/world",
                lambda sample: self._world_token(loop, sample.kind),
                history=True,  # the token there already: so its loss is seen too
            )
            await swarm.open()
            channel.send("world", Ready())
            epoch = await within(self._go, scenario.run.window_limit, "the world's go")
            if virtual:
                assert isinstance(loop, VirtualTimeLoop)
                first_end = min(self._bounds())
                loop.run_windows(Windows(loop, first_end, self._close, idle=self._tick))
                self._resumed = time.perf_counter()
            elif isinstance(clock, ScaledClock):
                clock.start_at_wall(epoch)
                await asyncio.sleep(max(0.0, epoch - time.time()))  # nothing before time 0
            swarm.start()
            beating = None if virtual else asyncio.ensure_future(self._beat())
            running = asyncio.ensure_future(swarm.run())
            stopping = asyncio.ensure_future(self._stop.wait())
            await asyncio.wait((running, stopping), return_when=asyncio.FIRST_COMPLETED)
            if running.done() and not running.cancelled() and running.exception() is not None:
                failed = f"{type(running.exception()).__name__}: {running.exception()}"
            elif running.done() and not stopping.done():
                # Every robot of this worker stopped, at this instant. The run goes on
                # until the world's Stop: the world decides how it ended (the other
                # workers' robots may still run, and it must see every window), and
                # these robots still answer what reaches them, as in one process.
                self._stopped_at = clock.now()
                await stopping
            stopping.cancel()
            running.cancel()
            if beating is not None:
                beating.cancel()
            with contextlib.suppress(BaseException):
                await running
        except Exception as exc:
            failed = f"{type(exc).__name__}: {exc}"
            traceback.print_exc()
        finally:
            if virtual and isinstance(loop, VirtualTimeLoop):
                loop.run_windows(Held())  # the robots stop at the run's last instant
            with contextlib.suppress(Exception):
                await swarm.halt()
                swarm.close()
            with contextlib.suppress(Exception):
                if failed is not None:
                    channel.send("world", Failed(failed))
                waits = round(self._waited, 3), round(self._waited_grant, 3)
                spread = self._spread()
                channel.send("world", Bye(self._final or self._counts(), *waits, *spread))
            for declared in (token, world_watch):
                if declared is not None:
                    with contextlib.suppress(Exception):
                        declared.undeclare()
            for checking in self._watching:
                checking.cancel()
            channel.close()
            session.close()
        if failed is None and self._world_lost is not None:
            failed = self._world_lost
        if failed is not None:
            print(f"worker {self._index}: {failed}", file=sys.stderr)
        return 1 if failed is not None else 0

    def _counts(self) -> Counts:
        counts = self._swarm.message_counts()
        refused = {} if self._channel is None else dict(self._channel.refused)
        if self._forged:
            refused["token.forged"] = self._forged
        faults = self._wire.stats if isinstance(self._wire, FaultyTransport) else None
        deliveries = Deliveries.of()
        return Counts(
            counts["internal"],
            counts["external"],
            self._swarm.drop_counts(),
            refused,
            faults,
            deliveries.late,
            round(deliveries.most_late, 4),
        )

    # -- virtual time: windows -----------------------------------------------------------

    async def _close(self, end: float, next_event: float) -> float | None:
        """Publishes window ``k``; the end of window ``k + 1`` once it may run (see _control)."""
        k = self._k
        recorder, network, channel = self._recorder, self._network, self._channel
        stop = self._stop
        assert recorder is not None and network is not None and channel is not None  # noqa: PT018
        assert stop is not None
        # The counts taken after the window before: counting every robot's counters takes
        # a while (13 ms for 1,250 robots), which is not spent while the others wait.
        counts, self._counts_due = self._counts_due, Counts()
        busy = time.perf_counter() - self._resumed
        halo, steps = self._halo, self._steps
        steps.ended(end)
        epoch = steps.epoch_at(end)
        cells = halo.own_cells(end) if halo is not None and epoch is not None else []
        # From now on this worker's events come at its next one, or at what the others
        # send it (no sooner than they promised), or once an epoch starts (others'
        # robots may come into range then, not before): its effects a latency later.
        heard, _ = self._bounds()
        soonest = min(next_event, heard, steps.next_epoch(end), steps.max_time)
        own = Window(
            k, next_event, recorder.take(), network.take_outgoing(), counts,
            until=end, promise=soonest + steps.latency, stopped_at=self._stopped_at,
            busy=busy, cells=cells,
        )  # fmt: skip
        channel.send(f"win/{self._index}", own)
        if epoch is not None:
            self._cells.setdefault(epoch, {})[self._index] = cells
        sent = time.perf_counter()
        if sent - self._counted_at >= COUNTS_EVERY:  # for the next window
            self._counted_at, self._counts_due = sent, self._counts()
        began = time.perf_counter()
        if halo is not None and epoch is not None:
            await self._turn(halo, epoch, end)
        for_grant = await self._until_free(end)
        self._resumed = time.perf_counter()
        self._waited += self._resumed - began
        self._waited_grant += for_grant
        if stop.is_set():
            self._final = self._counts()  # as the run ended: before the robots stop
            loop = asyncio.get_running_loop()
            if isinstance(loop, VirtualTimeLoop):
                loop.run_windows(Held())  # the robots stop at the run's last instant
            return None
        if halo is not None:
            self._depended += len(halo.dependencies)
            self._watched += network.watched
        self._k = k + 1
        return min(self._bounds())

    def _bounds(self) -> tuple[float, float]:
        """Where the next window may end: by what it heard and the steps; by the world's grant.

        Its robots' every event before it can run: no effect of another worker's
        robots reaches them sooner (the promises of the workers it depends on).
        """
        steps = self._steps
        heard = min((self._promised[w] for w in self._depends_on()), default=math.inf)
        free = min(heard, (steps.index + 1) * steps.credit, steps.max_time)
        return free, self._granted * steps.credit

    def _depends_on(self) -> Iterable[int]:
        """The workers whose robots may act on this one's now (every other without a range)."""
        if self._halo is not None:
            return self._halo.dependencies
        return self._promised.keys()

    async def _until_free(self, end: float) -> float:
        """Waits until a window after ``end`` may run (or the run stops); the wait for grants.

        A worker whose windows reached ``max_time`` waits for the world's :class:`Stop`.
        """
        stop, news = self._stop, self._news
        assert stop is not None and news is not None  # noqa: PT018
        for_grant, granted_from = 0.0, None
        while not stop.is_set():
            free, granted = self._bounds()
            if end < self._steps.max_time and min(free, granted) > end:
                break
            if free > end and granted_from is None and end < self._steps.max_time:
                granted_from = time.perf_counter()  # heard enough: waits for the world
            news.clear()
            await news.wait()
        if granted_from is not None:
            for_grant = time.perf_counter() - granted_from
        return for_grant

    async def _turn(self, halo: Halo, epoch: int, start: float) -> None:
        """Epoch ``epoch`` starts at ``start``: what this worker watches in it.

        Decided from every worker's cells at the epoch before's start (epoch 1: from
        where the robots start), it waits for those. The robots coming into sight
        are placed by the latest motion their workers said they started: it waits
        until those said everything up to ``start`` (promised no motion before it).
        """
        if epoch >= 2:
            workers = len(self._welcome.shares)
            await self._until(lambda: len(self._cells.get(epoch - 1, ())) >= workers)
            cells = self._cells.pop(epoch - 1, {})
            if len(cells) < workers:  # stopped meanwhile
                return
            halo.decide(cells[worker] for worker in sorted(cells))
        visible = halo.advance()
        promised = self._promised
        await self._until(lambda: all(promised[w] >= start for w in halo.dependencies))
        assert self._network is not None
        self._network.watch(visible)

    def _spread(self) -> tuple[float, float]:
        """The workers it depended on, and the others' robots it watched: means per window."""
        windows = max(1, self._k)
        return self._depended / windows, self._watched / windows

    async def _until(self, condition: Callable[[], bool]) -> None:
        """Waits until ``condition`` holds or the run is stopped."""
        stop, news = self._stop, self._news
        assert stop is not None and news is not None  # noqa: PT018
        while not stop.is_set() and not condition():
            news.clear()
            await news.wait()

    # -- scaled time: as it goes ---------------------------------------------------------

    def _schedule_flush(self) -> None:
        if not self._flushing:
            self._flushing = True
            asyncio.get_running_loop().call_soon(self._flush)

    def _flush(self) -> None:
        self._flushing = False
        if self._channel is None or self._network is None or self._recorder is None:
            return
        now = self._clock.now() if self._clock is not None else 0.0
        counts = Counts()
        if time.monotonic() - self._counted >= COUNTS_EVERY:
            self._counted, counts = time.monotonic(), self._counts()
        window = Window(
            -1, now, self._recorder.take(), self._network.take_outgoing(), counts,
            stopped_at=self._stopped_at,
        )  # fmt: skip
        self._channel.send(f"win/{self._index}", window)

    async def _beat(self) -> None:
        """Scaled time: where this worker's time is, every so often, also when nothing happens."""
        while True:
            await asyncio.sleep(HEARTBEAT)
            self._flush()
            self._check_world()

    # -- the world -----------------------------------------------------------------------

    def _tick(self) -> None:
        """Virtual time: the loop waited ~50 ms in vain for news; look at the wall clock."""
        self._check_world()
        if self._news is not None:
            self._news.set()

    def _world_token(self, loop: asyncio.AbstractEventLoop, kind: Any) -> None:
        """On a Zenoh thread: the world's token went (a hint to check, never proof)."""
        if kind == import_zenoh().SampleKind.DELETE:
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(self._world_suspected)

    def _world_suspected(self) -> None:
        self._watching.append(asyncio.ensure_future(self._suspect_world_unless_alive()))

    async def _suspect_world_unless_alive(self) -> None:
        """The world's token no longer answers: it has SUSPECT_LIMIT to say something."""
        key = f"{self._welcome.namespace}/world"
        if await asyncio.to_thread(token_lives, self._session, key):
            self._forged += 1  # another session's token of that name went: counted
        else:
            self._world_suspect = True

    def _check_world(self) -> None:
        """Stops this worker if the world said nothing for too long (see the module docs).

        The world beats every :data:`BEAT_EVERY`; a world whose token went has
        :data:`SUSPECT_LIMIT` to say something, any other :attr:`RunConfig.window_limit`.
        """
        if self._world_lost is not None:
            return
        limit = SUSPECT_LIMIT if self._world_suspect else self._scenario.run.window_limit
        if time.monotonic() - self._world_word <= limit:
            return
        self._world_lost = (
            f"the world is gone: its token went and no word came within {limit:g} s"
            if self._world_suspect
            else f"the world said nothing for {limit:g} s (run.window_limit): frozen, or cut off"
        )
        if self._stop is not None:
            self._stop.set()
        if self._go is not None and not self._go.done():
            self._go.set_exception(WorkerLost(self._world_lost))

    # -- what comes in -------------------------------------------------------------------

    def _heard(self, sender: int, window: Window) -> None:
        """Another worker's window: what its robots did and sent to ours, scheduled at once.

        On virtual time, it also promises when its next effect can come (see
        :meth:`_bounds`), and at an epoch's start says where its robots stand.
        """
        network, stop = self._network, self._stop
        if network is None or (stop is not None and stop.is_set()):
            return  # not started, or over: the robots here run nothing more
        network.receive(sender, window.observation, window.remote)
        if window.k < 0:
            return
        self._promised[sender] = max(self._promised.get(sender, 0.0), window.promise)
        epoch = self._steps.epoch_at(window.until)
        if epoch is not None:
            self._cells.setdefault(epoch, {})[sender] = window.cells

    def _on_message(self, suffix: str, sender: int, message: Control) -> None:
        if sender == WORLD:  # a signed word: it lives
            self._world_word, self._world_suspect = time.monotonic(), False
        match message:
            case Window() if sender != self._index and 0 <= sender < len(self._welcome.shares):
                self._heard(sender, message)
            case Grant(steps=steps) if sender == WORLD:
                self._granted = max(self._granted, steps)
            case Go(epoch=epoch) if sender == WORLD:
                if self._go is not None and not self._go.done():
                    self._go.set_result(epoch)
            case Stop() if sender == WORLD:
                if self._stop is not None:
                    self._stop.set()
        if self._news is not None:
            self._news.set()
