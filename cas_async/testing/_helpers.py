"""The helpers behind :mod:`cas_async.testing` (see there)."""

from __future__ import annotations

import asyncio
from collections import Counter
from collections.abc import Callable, Collection, Iterable, Sequence
from contextlib import AsyncExitStack
from typing import Any, Final, TypeVar, final

from .._clock import Clock, VirtualClock
from .._codec import Codec
from .._layer import Layer
from .._message import Message, spec_of
from .._robot import Robot
from .._swarm import Swarm
from .._virtual_loop import VirtualTimeLoop
from ..transport._base import Transport

__all__ = [
    "Recorder",
    "Robots",
    "RunUntilTimeout",
    "UnexpectedDrops",
    "assert_roundtrip",
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
    # In real time: the stdlib loop's queue of ready callbacks and heap of timers,
    # read only, after each pass.
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

    The condition is checked whenever every task is blocked, and every ``step``
    seconds. Seconds are the clock's (simulated) when ``clock`` is given, else the
    loop's (simulated on the virtual-time loop).

    Raises:
        RunUntilTimeout: still false after ``timeout`` seconds, naming ``what`` (or
            the condition).
    """
    now: Callable[[], float] = clock.now if clock is not None else asyncio.get_running_loop().time
    sleep = clock.sleep if clock is not None else asyncio.sleep
    deadline = now() + timeout
    while True:
        await wait_all_tasks_blocked()
        if condition():
            return
        left = deadline - now()
        if left <= 0:
            raise RunUntilTimeout(f"{what or _name_of(condition)} still false after {timeout:g} s")
        await sleep(min(step, left))


def _name_of(condition: Callable[[], object]) -> str:
    name = getattr(condition, "__qualname__", None) or repr(condition)
    return "the condition" if name == "<lambda>" else name


class Recorder(Layer):
    """A layer that records what reaches it, and answers requests with ``answer(msg)``.

    ``external`` and ``internal`` keep the messages that reached ``handle_msg`` and
    ``store_intra_msg``, in order; ``requests`` the NEGOTIATIONs it was asked (from
    another robot or from a neighbour). ``answer`` (default: none) returns the reply
    to a request, or ``None`` to leave it unanswered.

    Args:
        answer: the reply to a request.
    """

    def __init__(self, answer: Callable[[Message], Message | None] | None = None) -> None:
        self.external: list[Message] = []
        self.internal: list[Message] = []
        self.requests: list[Message] = []
        self._answer = answer

    def of_type(self, cls: type[M]) -> list[M]:
        """The messages of class ``cls`` that reached the layer, from outside or inside."""
        return [m for m in (*self.external, *self.internal) if isinstance(m, cls)]

    def get_msg_reply(self, msg: Message) -> Message | None:
        """An external request: recorded, and answered with ``answer`` at once."""
        self.requests.append(msg)
        return self._answer(msg) if self._answer is not None else None

    async def handle_msg(self, msg: Message) -> None:
        """Recorded (requests ``answer`` left unanswered too)."""
        self.external.append(msg)

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        """An internal request: recorded, and answered with ``answer``."""
        self.requests.append(msg)
        return self._answer(msg) if self._answer is not None else None

    async def store_intra_msg(self, msg: Message) -> None:
        """Recorded."""
        self.internal.append(msg)


def assert_roundtrip(
    msg: M, *, layers: int = 1, messages: Iterable[type[Message]] | None = None
) -> M:
    """Encodes ``msg`` as a robot of that stack would and decodes it; returns the copy.

    Header fields are kept as they are (set ``msg_id``, ``robot_id`` and the levels
    first to test them too).

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
    try:
        copy = codec.decode(codec.encode(msg))
    except Exception as exc:
        raise AssertionError(f"{msg!r} does not survive the codec: {exc}") from exc
    if type(copy) is not type(msg):
        raise AssertionError(f"{msg!r} came back as another class: {copy!r}")
    differ = [
        f"{name}: {getattr(msg, name)!r} became {getattr(copy, name)!r}"
        for name in (*spec_of(type(msg)).field_names, *_HEADER)
        if not _same(getattr(msg, name), getattr(copy, name))
    ]
    if differ:
        raise AssertionError(f"{msg!r} came back as {copy!r}: " + "; ".join(differ))
    return copy


def _same(a: object, b: object) -> bool:
    """Equal, NaN counting as equal to NaN (a float field may carry one)."""
    if isinstance(a, float) and isinstance(b, float) and a != a and b != b:
        return True
    try:
        return bool(a == b)
    except ValueError:  # numpy arrays: element-wise
        import numpy as np

        return bool(np.array_equal(a, b, equal_nan=True))  # type: ignore[arg-type]


_HEADER: Final = ("msg_id", "msg_type", "robot_id", "src_layer", "dst_layer", "corr_id")


class UnexpectedDrops(AssertionError):
    """Robots of a test dropped messages for reasons the test did not allow."""


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
        if clock is None and isinstance(asyncio.get_running_loop(), VirtualTimeLoop):
            clock = VirtualClock()
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
