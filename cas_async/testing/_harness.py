"""One layer under test, in a real robot, between scripted neighbours and scripted peers."""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Sequence
from typing import Any, final

from .. import Clock, Layer, LayerError, MemoryTransport, Message, Robot
from ._recorder import Recorder
from ._robots import Robots, UnexpectedDrops, default_clock
from ._waiting import wait_all_tasks_blocked

__all__ = ["LayerHarness", "Script"]


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

    :meth:`settle` lets what can happen *now* happen: simulated time does not move,
    so a timer the layer set for later (``wake_after``) has not gone off yet;
    :meth:`advance` moves time on (``await h.advance(1.0)``).

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
        self._robot: Robot | None = None

    async def __aenter__(self) -> LayerHarness:
        """Starts the robot and its peers (their layers too)."""
        transport = MemoryTransport()
        clock = default_clock(self._clock)
        layers: list[Layer] = list(self._own)
        layers[self.level] = self.layer
        robots = [Robot(self._robot_id, layers, transport=transport, clock=clock, **self._opts())]
        self._robot = robots[0]
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
        """Lets everything that can happen now happen (:func:`wait_all_tasks_blocked`).

        Messages are delivered and answered, hooks run, timers already due go off;
        simulated time does not move. A timer set for later has not gone off:
        :meth:`advance` moves time on to it (or use :func:`run_until` with the
        condition you expect and a ``timeout``).
        """
        await wait_all_tasks_blocked()

    async def advance(self, seconds: float) -> None:
        """Moves the robots' time on by ``seconds``, then :meth:`settle`.

        Every timer due meanwhile goes off at its instant, and what it sets in
        motion happens. On the virtual-time loop (``@pytest.mark.cas_virtual``)
        this takes no wall time; otherwise the robots' clock sleeps (real time,
        scaled by its time factor).

        Raises:
            ValueError: ``seconds`` is negative or not a number.
            RuntimeError: the harness has not started (use ``async with``).
        """
        if not seconds >= 0:
            raise ValueError(f"advance(seconds): seconds must be >= 0, got {seconds!r}")
        if self._robot is None:
            raise RuntimeError("LayerHarness.advance: start the harness first (async with)")
        clock = self._robot.clock
        await clock.sleep_until(clock.now() + seconds)  # lands on the instant itself
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
