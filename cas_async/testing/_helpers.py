"""The helpers behind :mod:`cas_async.testing` (see there)."""

from __future__ import annotations

import asyncio
import contextlib
import os
import typing
import weakref
from collections import Counter
from collections.abc import AsyncIterator, Callable, Collection, Iterable, Mapping, Sequence
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, TypeVar, final

import msgspec
import numpy as np

from .._clock import Clock, VirtualClock
from .._codec import Codec
from .._errors import LayerError
from .._layer import Layer
from .._message import Message, field_names
from .._robot import Robot
from .._runner import run as run_loop
from .._swarm import Swarm
from .._virtual_loop import VirtualTimeLoop
from ..scenario import RunResult, ScenarioRun, Trace, load_scenario
from ..sim import Environment
from ..transport._base import Transport
from ..transport._memory import MemoryTransport

__all__ = [
    "LayerHarness",
    "Recorder",
    "Robots",
    "RunUntilTimeout",
    "ScenarioOutcome",
    "Script",
    "UnexpectedDrops",
    "assert_roundtrip",
    "peer_process",
    "run_scenario_file",
    "run_until",
    "wait_all_tasks_blocked",
]

M = TypeVar("M", bound=Message)

_MAX_PASSES: Final = 100_000
"""Loop passes :func:`wait_all_tasks_blocked` waits before it calls the loop busy."""


async def wait_all_tasks_blocked() -> None:
    """Returns once every other task of the loop is blocked: waiting, with nothing to do now.

    Messages between robots of a :class:`~cas_async.MemoryTransport`, hooks, layer
    tasks and timers already due all run first; simulated time does not move. Use it
    where a test must let everything settle before it looks (``trio.testing`` has
    the same). Exact on the stdlib and virtual-time loops; on another loop (uvloop)
    it raises :class:`TypeError`.

    Raises:
        TypeError: the running loop does not show its ready callbacks.
        RuntimeError: the loop stayed busy for 100,000 passes: a task never blocks.
    """
    loop = asyncio.get_running_loop()
    if isinstance(loop, VirtualTimeLoop):  # it knows when it is idle
        await loop.idle()
        return
    # In real time one task per loop watches (two would each see the other busy);
    # every caller waits for its verdict.
    probe = _probes.get(loop)
    if probe is None or probe.done():
        probe = _probes[loop] = loop.create_task(_probe(loop))
    await asyncio.shield(probe)


_probes: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, asyncio.Task[None]] = (
    weakref.WeakKeyDictionary()
)


async def _probe(loop: asyncio.AbstractEventLoop) -> None:
    # The stdlib loop's queue of ready callbacks and heap of timers (no public API
    # shows them), read only, after each pass.
    ready = getattr(loop, "_ready", None)
    scheduled = getattr(loop, "_scheduled", None)
    if ready is None or scheduled is None:
        raise TypeError(
            f"wait_all_tasks_blocked needs the stdlib or virtual-time loop, not {type(loop)!r}"
        )
    for _ in range(_MAX_PASSES):
        await asyncio.sleep(0)
        if not ready and not (scheduled and scheduled[0].when() <= loop.time()):
            return
    raise RuntimeError(f"the loop is still busy after {_MAX_PASSES} passes: a task never waits")


class RunUntilTimeout(AssertionError):
    """:func:`run_until`'s condition stayed false for its whole timeout."""


async def run_until(
    condition: Callable[[], object],
    *,
    timeout: float,
    clock: Clock | None = None,
    step: float = 0.01,
    what: str | None = None,
) -> None:
    """Lets the robots run until ``condition()`` is true, for ``timeout`` seconds at most.

    The condition is checked whenever every task is blocked: on the virtual-time
    loop at every instant something happens (time jumps from one timer to the
    next), on other loops also every ``step`` seconds. Seconds are the clock's
    (simulated) when ``clock`` is given, else the loop's (simulated on the
    virtual-time loop).

    Raises:
        RunUntilTimeout: still false after ``timeout`` seconds, naming ``what`` (or
            the condition).
    """
    loop = asyncio.get_running_loop()
    now: Callable[[], float] = clock.now if clock is not None else loop.time
    deadline = now() + timeout
    while True:
        await wait_all_tasks_blocked()
        if condition():
            return
        left = deadline - now()
        if left <= 0:
            raise RunUntilTimeout(f"{what or _name_of(condition)} still false after {timeout:g} s")
        if isinstance(loop, VirtualTimeLoop) and clock is None:
            # Nothing changes before the next timer goes off: wake up right after it.
            later = [t - loop.time() for t in loop.timer_deadlines() if t > loop.time()]
            await asyncio.sleep(min([*later, left]))
        elif clock is not None:
            await clock.sleep(min(step, left))
        else:
            await asyncio.sleep(min(step, left))


def _name_of(condition: Callable[[], object]) -> str:
    name = getattr(condition, "__qualname__", None) or repr(condition)
    return "the condition" if name == "<lambda>" else name


class Recorder(Layer):
    """A layer that records what reaches it, and answers requests with ``answer(msg)``.

    ``arrived`` keeps every message that reached the layer, in the order the layer
    took them (a request answered with ``answer`` the moment it arrives, the others
    when the layer's task gets to them); ``external``
    and ``internal`` those that reached ``handle_msg`` and ``store_intra_msg``;
    ``requests`` the NEGOTIATIONs it was asked (by another robot or a neighbour).
    ``answer`` (default: none) returns the reply to a request, or ``None`` to leave
    it unanswered (an external one then reaches ``handle_msg``).

    Args:
        answer: the reply to a request.
    """

    def __init__(self, answer: Callable[[Message], Message | None] | None = None) -> None:
        self.arrived: list[Message] = []
        self.external: list[Message] = []
        self.internal: list[Message] = []
        self.requests: list[Message] = []
        self._answer = answer

    def of_type(self, cls: type[M]) -> list[M]:
        """The messages of class ``cls`` that reached the layer, in order."""
        return [m for m in self.arrived if isinstance(m, cls)]

    def get_msg_reply(self, msg: Message) -> Message | None:
        """An external request: recorded, and answered with ``answer`` at once."""
        self.requests.append(msg)
        reply = self._answer(msg) if self._answer is not None else None
        if reply is not None:  # else it reaches handle_msg, which records it
            self.arrived.append(msg)
        return reply

    async def handle_msg(self, msg: Message) -> None:
        """Recorded."""
        self.arrived.append(msg)
        self.external.append(msg)

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        """An internal request: recorded, and answered with ``answer``."""
        self.arrived.append(msg)
        self.requests.append(msg)
        return self._answer(msg) if self._answer is not None else None

    async def store_intra_msg(self, msg: Message) -> None:
        """Recorded."""
        self.arrived.append(msg)
        self.internal.append(msg)


def assert_roundtrip(
    msg: M, *, layers: int = 1, messages: Iterable[type[Message]] | None = None
) -> M:
    """Encodes ``msg`` as a robot of that stack would and decodes it; returns the copy.

    Header fields are kept as they are (set ``msg_id``, ``robot_id`` and the levels
    first to test them too); a ``msg_id`` of 0 (not sent) travels as 1, since no
    datagram carries id 0, and comes back as 0.

    Args:
        msg: the message.
        layers: the stack's height.
        messages: the stack's messages (default: ``msg``'s class alone).

    Raises:
        AssertionError: the copy differs from ``msg`` (the fields that differ are
            named), or the message cannot be encoded or decoded (with the codec's
            reason).
    """
    codec = Codec.for_stack(layers, [type(msg)] if messages is None else messages)
    sent = msg
    if not msg.msg_id:  # not sent yet: no datagram carries id 0, so it travels as 1
        sent = msgspec.structs.replace(msg, msg_id=1)
    try:
        copy = codec.decode(codec.encode(sent))
    except Exception as exc:
        raise AssertionError(f"{msg!r} does not survive the codec: {exc}") from exc
    if sent is not msg:
        copy.msg_id = 0
    if type(copy) is not type(msg):
        raise AssertionError(f"{msg!r} came back as another class: {copy!r}")
    differ = [
        f"{name}: {getattr(msg, name)!r} became {getattr(copy, name)!r}"
        for name in (*field_names(type(msg)), *_HEADER)
        if not _same(getattr(msg, name), getattr(copy, name))
    ]
    if differ:
        raise AssertionError(f"{msg!r} came back as {copy!r}: " + "; ".join(differ))
    return copy


def _same(a: object, b: object) -> bool:
    """Equal, NaN counting as equal to NaN wherever it is (a float, in a list, an array)."""
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (a != a and b != b)
    if isinstance(a, list | tuple) and type(a) is type(b):
        other = typing.cast(Sequence[object], b)
        return len(a) == len(other) and all(_same(x, y) for x, y in zip(a, other, strict=True))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, msgspec.Struct) and type(a) is type(b):
        names = field_names(type(a)) if isinstance(a, Message) else type(a).__struct_fields__
        return all(_same(getattr(a, name), getattr(b, name)) for name in names)
    if isinstance(a, np.ndarray) and isinstance(b, np.ndarray):
        floating = a.dtype.kind in "fc"
        return a.dtype == b.dtype and bool(np.array_equal(a, b, equal_nan=floating))
    return bool(a == b)


_HEADER: Final = ("msg_id", "msg_type", "robot_id", "src_layer", "dst_layer", "corr_id")


class UnexpectedDrops(AssertionError):
    """Robots of a test dropped messages for reasons the test did not allow."""


def _default_clock(clock: Clock | None) -> Clock | None:
    """``clock``, or on the virtual-time loop a :class:`~cas_async.VirtualClock`."""
    if clock is None and isinstance(asyncio.get_running_loop(), VirtualTimeLoop):
        return VirtualClock()
    return clock


@final
class Robots:
    """Starts robots and swarms for a test; :meth:`aclose` stops them and checks them.

    Args:
        allowed_drops: drop reasons that are no failure (``robot.dropped``); any
            other makes :meth:`aclose` raise :class:`UnexpectedDrops`.
        messages: the messages of robots started without ``messages=`` (default:
            every registered message).
    """

    def __init__(
        self,
        *,
        allowed_drops: Collection[str] = (),
        messages: Sequence[type[Message]] | None = None,
    ) -> None:
        self.allowed_drops = set(allowed_drops)
        self._messages = messages
        self._stack = AsyncExitStack()
        self._robots: list[Robot] = []

    async def start(
        self,
        robot_id: int,
        layers: Sequence[Layer],
        *,
        transport: Transport | None = None,
        clock: Clock | None = None,
        **options: Any,
    ) -> Robot:
        """Makes and starts a robot (see :class:`~cas_async.Robot`); stopped by :meth:`aclose`.

        On the virtual-time loop the clock defaults to a :class:`~cas_async.VirtualClock`.
        """
        clock = _default_clock(clock)
        if self._messages is not None:
            options.setdefault("messages", self._messages)
        robot = Robot(robot_id, layers, transport=transport, clock=clock, **options)
        await self._stack.enter_async_context(robot)
        self._robots.append(robot)
        return robot

    async def swarm(self, robots: Iterable[Robot]) -> Swarm:
        """Starts ``robots`` (made, not started) as one swarm; stopped by :meth:`aclose`."""
        members = list(robots)
        swarm = await self._stack.enter_async_context(Swarm(members))
        self._robots.extend(members)
        return swarm

    @property
    def robots(self) -> tuple[Robot, ...]:
        """The robots started so far, in order."""
        return tuple(self._robots)

    def drops(self) -> dict[int, dict[str, int]]:
        """What each robot dropped so far, by reason (robots that dropped nothing left out)."""
        return {robot.robot_id: dict(robot.dropped) for robot in self._robots if robot.dropped}

    async def aclose(self) -> None:
        """Stops and closes every robot, the last started first.

        Raises:
            ~cas_async.LayerError: a layer of a robot failed (the first such failure).
            UnexpectedDrops: a robot dropped a message for a reason not allowed.
        """
        await self._stack.aclose()  # raises a robot's LayerError
        unexpected = {
            robot_id: {r: n for r, n in reasons.items() if r not in self.allowed_drops}
            for robot_id, reasons in self.drops().items()
        }
        unexpected = {robot_id: reasons for robot_id, reasons in unexpected.items() if reasons}
        if unexpected:
            total: Counter[str] = Counter()
            for reasons in unexpected.values():
                total.update(reasons)
            lines = [f"robot {rid}: {reasons}" for rid, reasons in sorted(unexpected.items())]
            raise UnexpectedDrops(
                f"robots dropped messages ({dict(total)}); allow a reason with "
                "cas_robots.allowed_drops.add(reason) if the test expects it:\n  "
                + "\n  ".join(lines)
            )


@dataclass(frozen=True)
class ScenarioOutcome:
    """What :func:`run_scenario_file` ran: the result, the trace, and the world at the end.

    Attributes:
        result: what the run measured (``results.json``'s figures).
        trace: where the robots were over simulated time.
        environment: the simulated world as the run left it (its item ledger too).
    """

    result: RunResult
    trace: Trace
    environment: Environment


def run_scenario_file(
    path: str | os.PathLike[str],
    *overrides: str,
    virtual: bool = True,
    observe: Callable[[Environment], None] | None = None,
) -> ScenarioOutcome:
    """Loads a scenario file, runs it to its end, and returns what it measured.

    On virtual time with the in-memory transport by default (fast, and the same
    seed gives the same run); ``overrides`` are ``--set`` strings
    (``"strategy.name=solo"``). For a plain (synchronous) test: it runs its own
    event loop.

    Args:
        path: the scenario file.
        overrides: ``KEY=VALUE`` settings, applied after the file's.
        virtual: run on virtual time with the memory transport (``run.virtual``,
            ``run.transport``); ``False`` runs the file's own settings.
        observe: called with the Environment before the robots start.

    Raises:
        cas_async.scenario.ScenarioError: the file or an override is wrong.
        RuntimeError: called from a running event loop (await
            ``cas_async.scenario.run_scenario`` there instead).
    """
    settings = ["run.virtual=true", 'run.transport="memory"'] if virtual else []
    scenario = load_scenario(Path(path), [*settings, *overrides])

    async def run() -> ScenarioOutcome:
        scenario_run = ScenarioRun(scenario, observe=observe)
        async with scenario_run:
            await scenario_run.until_done()
        return ScenarioOutcome(scenario_run.result, scenario_run.trace, scenario_run.environment)

    try:
        asyncio.get_running_loop()
    except RuntimeError:
        pass
    else:
        raise RuntimeError(
            "run_scenario_file runs its own event loop: in an async test, "
            "await cas_async.scenario.run_scenario(load_scenario(...)) instead"
        )
    outcome: ScenarioOutcome = run_loop(run(), virtual=scenario.run.virtual)
    return outcome


# -- one layer in isolation -------------------------------------------------------------------

Script = Callable[[Message], Message | None]
"""A scripted answer: what a request gets back, or ``None`` to leave it unanswered."""


class _Scripted(Recorder):
    """A scripted neighbour or peer layer: records, answers by the class of the request."""

    def __init__(self) -> None:
        super().__init__(answer=self._reply)
        self.answers: dict[type[Message], Script] = {}

    def _reply(self, msg: Message) -> Message | None:
        for cls in type(msg).__mro__:
            answer = self.answers.get(cls)
            if answer is not None:
                return answer(msg)
        return None


@final
class LayerHarness:
    """A layer under test, between scripted neighbours, with scripted peer robots.

    The layer runs in a real robot of ``height`` layers, at ``level``; every other
    layer of that robot is a scripted :class:`Recorder`; each robot of ``peers`` is
    a real robot of the same height whose layer at ``level`` is one too. Messages
    travel through the real runtime and codec (on a :class:`~cas_async.MemoryTransport`),
    so the layer sees exactly what it would in a swarm::

        async with LayerHarness(MyStrategy(params), level=1, height=5, peers=[3]) as h:
            h.answer_below(RequestRobotsInRange, lambda m: RobotsInRange(...))
            h.from_above(MoveBucket(bucket=1, ...))
            await h.settle()
            assert h.sent_to(3) == [RequestPartner(...)]

    Args:
        layer: the layer under test.
        level: its level (0 is the top).
        height: the robot's number of layers.
        robot_id: the robot's id.
        peers: the ids of the peer robots (same height, scripted at ``level``).
        messages: the messages of the stack (default: every registered message).
        clock: the clock (default: a :class:`~cas_async.VirtualClock` on the
            virtual-time loop, else the robots' default).
        allowed_drops: drop reasons that do not fail the harness (see :class:`Robots`).
    """

    def __init__(
        self,
        layer: Layer,
        *,
        level: int = 0,
        height: int = 1,
        robot_id: int = 1,
        peers: Iterable[int] = (),
        messages: Sequence[type[Message]] | None = None,
        clock: Clock | None = None,
        allowed_drops: Collection[str] = (),
    ) -> None:
        if not 0 <= level < height:
            raise ValueError(f"level {level} is not in a stack of {height} layers")
        self.layer = layer
        self.level = level
        self._height = height
        self._robot_id = robot_id
        self._peer_ids = tuple(peers)
        if robot_id in self._peer_ids:
            raise ValueError(f"robot {robot_id} cannot be its own peer")
        self._messages = messages
        self._clock = clock
        self._own = [_Scripted() for _ in range(height)]
        self._peers = {peer: _Scripted() for peer in self._peer_ids}
        self.robots = Robots(messages=messages, allowed_drops=allowed_drops)

    async def __aenter__(self) -> LayerHarness:
        """Starts the robot and its peers (their layers too)."""
        transport = MemoryTransport()
        clock = _default_clock(self._clock)
        layers: list[Layer] = list(self._own)
        layers[self.level] = self.layer
        robots = [Robot(self._robot_id, layers, transport=transport, clock=clock, **self._opts())]
        for peer, scripted in self._peers.items():
            stack: list[Layer] = [_Scripted() for _ in range(self._height)]
            stack[self.level] = scripted
            robots.append(Robot(peer, stack, transport=transport, clock=clock, **self._opts()))
        await self.robots.swarm(robots)
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: object
    ) -> None:
        """Stops everything; raises the layer's failure, or drops the test did not allow.

        When the block itself raised, that error goes on, with what stopping found
        added to it as a note.
        """
        try:
            await self.robots.aclose()
        except (LayerError, UnexpectedDrops) as found:
            if exc is None:
                raise
            exc.add_note(f"and when the harness stopped: {found}")

    def _opts(self) -> dict[str, Any]:
        return {} if self._messages is None else {"messages": self._messages}

    # -- what the layer is given --------------------------------------------------------

    def from_above(self, msg: Message) -> None:
        """The layer above sends ``msg`` down to the layer (``send_down``)."""
        self._neighbour(-1, "above").send_down(msg)

    def from_below(self, msg: Message) -> None:
        """The layer below sends ``msg`` up to the layer (``send_up``)."""
        self._neighbour(+1, "below").send_up(msg)

    def from_peer(self, peer: int, msg: Message) -> None:
        """Peer robot ``peer``'s layer of the same level sends ``msg`` to the layer."""
        self._peer(peer).send(self._robot_id, msg)

    async def request_from_peer(self, peer: int, msg: Message, *, timeout: float = 1.0) -> Message:
        """Peer ``peer`` asks the layer ``msg`` (a request) and returns its answer."""
        return await self._peer(peer).request(self._robot_id, msg, timeout=timeout)

    def answer_at(self, level: int, cls: type[Message], answer: Script) -> None:
        """How the robot's layer at ``level`` answers the requests of class ``cls`` it gets."""
        if level == self.level or not 0 <= level < self._height:
            raise ValueError(f"level {level} is not a scripted layer of this harness")
        self._own[level].answers[cls] = answer

    def answer_above(self, cls: type[Message], answer: Script) -> None:
        """How the layer above answers the layer's requests of class ``cls``."""
        self._own[self._index(-1, "above")].answers[cls] = answer

    def answer_below(self, cls: type[Message], answer: Script) -> None:
        """How the layer below answers the layer's requests of class ``cls``."""
        self._own[self._index(+1, "below")].answers[cls] = answer

    def answer_peer(self, peer: int, cls: type[Message], answer: Script) -> None:
        """How peer ``peer`` answers the layer's requests of class ``cls``."""
        self._peer(peer).answers[cls] = answer

    # -- what the layer did -------------------------------------------------------------

    @property
    def sent_up(self) -> list[Message]:
        """What reached the layer above from the layer, in order (requests included)."""
        return list(self._own[self._index(-1, "above")].arrived)

    @property
    def sent_down(self) -> list[Message]:
        """What reached the layer below from the layer, in order (requests included)."""
        return list(self._own[self._index(+1, "below")].arrived)

    def sent_to(self, peer: int) -> list[Message]:
        """What reached peer ``peer`` from the layer, in order (requests included)."""
        return list(self._peer(peer).arrived)

    async def settle(self) -> None:
        """Lets everything that can happen now happen (:func:`wait_all_tasks_blocked`)."""
        await wait_all_tasks_blocked()

    # -- helpers -------------------------------------------------------------------------

    def _index(self, step: int, where: str) -> int:
        index = self.level + step
        if not 0 <= index < self._height:
            raise ValueError(f"the layer at level {self.level} has no layer {where}")
        return index

    def _neighbour(self, step: int, where: str) -> Layer:
        return self._own[self._index(step, where)]

    def _peer(self, peer: int) -> _Scripted:
        scripted = self._peers.get(peer)
        if scripted is None:
            raise ValueError(f"robot {peer} is not a peer of this harness: {self._peer_ids}")
        return scripted


# -- a peer in another process ----------------------------------------------------------------


@asynccontextmanager
async def peer_process(
    *argv: str, ready: str = "ready", timeout: float = 10.0, env: Mapping[str, str] | None = None
) -> AsyncIterator[asyncio.subprocess.Process]:
    """Starts ``argv``, waits until it prints the line ``ready``, and always ends it after.

    For tests with robots in another process (real UDP on loopback, say). Its stdin
    and stdout are pipes (what it prints after ``ready`` is the test's to read); its
    stderr is read all along (so that it never blocks on a full pipe) and its end
    quoted if the process dies before it is ready. Leaving the block kills the
    process if it still runs and reaps it (5 s at most), whatever happened in the
    block.

    Raises:
        TimeoutError: no ``ready`` line within ``timeout`` (wall) seconds.
        RuntimeError: the process ended before it was ready (with its exit status
            and the end of its stderr), or the loop runs on virtual time (where
            waiting for another process cannot be timed).
    """
    if isinstance(asyncio.get_running_loop(), VirtualTimeLoop):
        raise RuntimeError("peer_process needs a real-time loop (not @pytest.mark.cas_virtual)")
    process = await asyncio.create_subprocess_exec(
        *argv,
        stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        env=None if env is None else dict(env),
    )
    stdout, stderr = process.stdout, process.stderr
    if stdout is None or stderr is None:  # pragma: no cover - pipes were asked for
        raise RuntimeError("asyncio gave the process no pipes")
    said = bytearray()  # the end of its stderr
    draining = asyncio.ensure_future(_drain(stderr, said))
    try:
        try:
            async with asyncio.timeout(timeout):
                while (line := await stdout.readline()).decode().strip() != ready:
                    if not line:  # end of output: the process is gone
                        status = await process.wait()
                        await draining
                        raise RuntimeError(
                            f"{argv[0]} ended (exit {status}) before printing {ready!r}: "
                            + said.decode(errors="replace")
                        )
        except TimeoutError:
            raise TimeoutError(f"{argv[0]} did not print {ready!r} within {timeout:g} s") from None
        yield process
    finally:
        if process.returncode is None:
            with contextlib.suppress(ProcessLookupError):  # it may have just ended
                process.kill()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(5.0):
                # Reaped, and its pipes read to the end: asyncio then closes them.
                await asyncio.gather(process.wait(), stdout.read(), draining)
        draining.cancel()
        if process.stdin is not None:
            process.stdin.close()


async def _drain(stream: asyncio.StreamReader, tail: bytearray, keep: int = 500) -> None:
    """Reads ``stream`` to its end, keeping its last ``keep`` bytes in ``tail``."""
    while chunk := await stream.read(65536):
        tail += chunk
        del tail[:-keep]
