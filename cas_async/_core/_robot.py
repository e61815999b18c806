"""``Robot``: an ordered stack of layers, its transport endpoint, and their lifecycle.

The thesis's RobotArchitecture/RobotImplementation with ConnectLayers, StartProcess
and EndProcess::

    robot = Robot(robot_id=3, layers=[Top(), Middle(), Bottom()], transport=..., clock=...)
    async with robot:          # opens the endpoint, starts one task per layer
        await robot.run()      # until every termination_condition() holds
    # leaving the block cancels the layer tasks and closes the endpoint

The robot owns its parts: one :class:`~cas_async._core._layer_runtime.LayerRuntime` per
layer, one :class:`~cas_async._core._outbox.Outbox` that every outgoing external message
leaves through, one :class:`~cas_async._core._reception.Reception` that every incoming
datagram enters through, and one count of dropped messages they all add to.

The layer tasks live in an ``asyncio.TaskGroup`` owned by a supervisor task, so the
code that embeds a robot is never cancelled by it: when a layer raises, its siblings
are cancelled and ``run()`` (or leaving the ``async with``) raises
:class:`~cas_async.LayerError` naming the robot and layer, with the original
exception as ``__cause__``.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterable, Sequence
from typing import Any, final

from .._errors import ConfigurationError, RobotStateError
from .._time._clock import Clock, ScaledClock
from .._types import Address, Level, RobotId
from .._wire._codec import DEFAULT_MAX_DATAGRAM, MIN_DATAGRAM, Codec
from .._wire._message import Message
from ._channel import DEFAULT_QUEUE_LIMIT
from ._counters import LayerCounters
from ._dedup import ID_SLACK, ReplyCache
from ._hooks import Overrides
from ._layer import Layer, attach, overrides
from ._layer_runtime import LayerRuntime
from ._logs import DropLog, logger_for
from ._outbox import Outbox
from ._reception import Reception
from ._robot_state import RobotState
from ._supervision import RestartPolicy, run_layer
from ._transport_contract import Transport

__all__ = ["Robot"]


@final
class Robot:
    """A robot: layers (index 0 = top), an optional transport, and a clock.

    Lifecycle (see :class:`RobotState`): ``async with robot:`` opens the endpoint
    and starts one task per layer; leaving the block stops the tasks and closes the
    endpoint. Code that starts many robots together (as :class:`~cas_async.Swarm`
    does) uses the two halves of each step: :meth:`open` every robot, then
    :meth:`start` every robot, so that no layer sends to a robot whose endpoint
    does not exist yet; :meth:`halt` every robot, then :meth:`close` every robot,
    so that no robot still running sends to one that is gone.

    Args:
        robot_id: unique in the swarm.
        layers: the stack, top first; each layer instance belongs to one robot.
        transport: how external messages travel; without one, ``send`` raises.
        clock: simulated time; real time (``ScaledClock(1.0)``) by default.
        messages: the message classes this robot's stack uses; they define the
            stack fingerprint. Default: every message class defined. Pass it when one
            process holds messages of several applications (e.g. a test session).
        max_datagram_size: largest datagram encoded or accepted (also capped by the
            transport's own limit).
        queue_limit: pending messages per layer at which the queue is full: external
            messages are then dropped and counted, and a layer sending internal
            messages to it waits until it has drained to half (internal messages
            are never dropped).
        restart: restart a layer that raises, within these limits, instead of
            stopping the robot (see :class:`~cas_async.RestartPolicy`).
        reply_memory: simulated seconds a reply to another robot is kept at least,
            to answer a repetition of its request (its asker lost the reply): longer
            than any asker's retries last (``(retries + 1) * timeout``). Older
            replies go as new ones are kept (see :class:`~cas_async._core._dedup.ReplyCache`);
            kept replies take at most about 1 MiB, beyond which the older half goes.
    """

    def __init__(
        self,
        robot_id: RobotId,
        layers: Sequence[Layer],
        *,
        transport: Transport | None = None,
        clock: Clock | None = None,
        messages: Iterable[type[Message]] | None = None,
        max_datagram_size: int = DEFAULT_MAX_DATAGRAM,
        queue_limit: int = DEFAULT_QUEUE_LIMIT,
        restart: RestartPolicy | None = None,
        reply_memory: float = 60.0,
    ) -> None:
        if type(robot_id) is not int:
            raise ConfigurationError(f"robot_id must be an int, got {robot_id!r}")
        if not layers:
            raise ConfigurationError(f"robot {robot_id}: a robot needs at least one layer")
        if not reply_memory >= 0:
            raise ConfigurationError(
                f"robot {robot_id}: reply_memory must be >= 0 seconds, got {reply_memory!r}"
            )
        if max_datagram_size < MIN_DATAGRAM or queue_limit < 1:
            raise ConfigurationError(
                f"robot {robot_id}: max_datagram_size must be at least {MIN_DATAGRAM} bytes "
                f"and queue_limit at least 1 (got {max_datagram_size}, {queue_limit})"
            )
        self.robot_id = robot_id
        self.transport = transport
        self.clock: Clock = clock if clock is not None else ScaledClock(1.0)
        self.queue_limit = queue_limit
        self.restart = restart
        self.reply_memory = reply_memory
        self._messages = None if messages is None else tuple(messages)
        self._max_datagram_size = max_datagram_size
        self._log = logger_for(robot_id)
        self._drops = DropLog(self._log)
        self._outbox = Outbox(robot_id, self._drops)
        self._state = RobotState.CREATED
        self._supervisor: asyncio.Task[None] | None = None
        self._stop_requested = asyncio.Event()
        self._done = asyncio.Event()  # run() returns once set
        self._outcome: BaseException | None = None  # what run() raises once done
        self._failure: BaseException | None = None  # a layer's failure, raised once
        self._judges: list[LayerRuntime] = []
        self._runtimes = attach(robot_id, layers, self._runtime_for)
        for runtime in self._runtimes:
            runtime.link(self._runtimes)
        self.layers: tuple[Layer, ...] = tuple(layers)
        self._reception = Reception(self._runtimes, self._outbox, self._drops, self._log)

    def _runtime_for(self, layer: Layer, level: Level) -> LayerRuntime:
        """Thesis ConnectLayers: the runtime of the layer at ``level``."""
        name = type(layer).__name__
        judges = overrides(layer, "termination_condition")
        runtime = LayerRuntime(
            layer,
            self,
            level,
            name=name,
            log=logger_for(self.robot_id, name, level),
            outbox=self._outbox,
            drops=self._drops,
            queue_limit=self.queue_limit,
            overrides=Overrides(
                inner=overrides(layer, "inner_process"),
                answers=overrides(layer, "get_msg_reply"),
                membership=overrides(layer, "on_robot_joined") or overrides(layer, "on_robot_left"),
            ),
            on_batch=self._layer_may_be_done if judges else None,
        )
        if judges:
            self._judges.append(runtime)
        return runtime

    # -- introspection -----------------------------------------------------------------

    @property
    def state(self) -> RobotState:
        """CREATED, OPEN, RUNNING or STOPPED."""
        return self._state

    @property
    def fingerprint(self) -> int:
        """This robot's stack fingerprint (known once opened).

        Raises:
            RobotStateError: the robot has not been opened yet.
        """
        return self._outbox.codec.fingerprint

    @property
    def address(self) -> Address | None:
        """Where other robots reach this one, once started with a transport."""
        return self._outbox.address

    @property
    def dropped(self) -> dict[str, int]:
        """Messages dropped so far, by reason."""
        return dict(self._drops.counts)

    def counters(self) -> dict[str, int]:
        """Message counters summed over the layers, ``replies_resent`` and ``dropped.<reason>``.

        ``replies_resent`` counts kept replies sent again to a repeated request.
        """
        total = LayerCounters()
        for runtime in self._runtimes:
            total.add(runtime.counters)
        counts = total.as_dict()
        counts["replies_resent"] = self._outbox.replies_resent
        counts.update({f"dropped.{reason}": n for reason, n in sorted(self._drops.counts.items())})
        return counts

    def message_counts(self) -> dict[str, dict[str, int]]:
        """Messages this robot's layers sent, by class name, internal and external.

        Returns ``{"internal": {name: n}, "external": {name: n}}``. Forwarding is not
        counted again; a broadcast counts once per recipient.
        """
        internal: dict[str, int] = {}
        external: dict[str, int] = {}
        for runtime in self._runtimes:
            runtime.counters.add_by_name(internal, external)
        return {"internal": internal, "external": external}

    def add_message_counts(
        self, internal: dict[type[Any], int], external: dict[type[Any], int]
    ) -> None:
        """Adds what :meth:`message_counts` counts to ``internal`` and ``external``, by class."""
        for runtime in self._runtimes:
            runtime.counters.add_by_type(internal, external)

    def unanswered_requests(self) -> dict[str, int]:
        """Internal requests waiting now that their asked layer did not answer, by who asked what.

        A layer's ``get_intra_msg_reply`` that returns ``None`` leaves the asker
        waiting until a ``reply()`` comes or its timeout ends (never, with
        ``math.inf``). Those still waiting are counted here, as ``{"Plan(L0) asked
        Drive(L1) for GoTo": 2}``: the scenario runner reports them when a run ends.
        """
        counts: dict[str, int] = {}
        for runtime in self._runtimes:
            for request, asked in runtime.requests.unanswered():
                key = f"{runtime.name}(L{runtime.level}) asked {asked} for {request}"
                counts[key] = counts.get(key, 0) + 1
        return counts

    def inbox_sizes(self) -> tuple[int, ...]:
        """Messages waiting in each layer's inbox, top first: how far each layer is behind."""
        return tuple(len(runtime.inbox) for runtime in self._runtimes)

    def last_heard(self, robot_id: RobotId) -> float | None:
        """Simulated time of the latest message delivered from ``robot_id``, or ``None``.

        Every message accepted from it counts (a duplicate too), so a partner that
        goes quiet shows as a growing ``clock.now() - last_heard(partner)``.
        """
        heard = self._reception.last_heard(robot_id)
        return None if heard is None else self.clock.at_loop_time(heard)

    def __repr__(self) -> str:
        names = ", ".join(runtime.name for runtime in self._runtimes)
        return f"Robot({self.robot_id}, [{names}], {self._state})"

    # -- lifecycle ---------------------------------------------------------------------

    async def __aenter__(self) -> Robot:
        """StartProcess: opens the endpoint and starts one task per layer."""
        await self.open()
        self.start()
        return self

    async def __aexit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: object
    ) -> None:
        """EndProcess: cancels the layer tasks, waits for them, closes the endpoint.

        Raises:
            LayerError: a layer failed and ``run()`` did not already raise it.
        """
        if self._state is not RobotState.RUNNING:
            return
        try:
            await self.halt()
        finally:
            self.close()
        failure = self.take_failure()
        if failure is not None:
            if exc is None:
                raise failure
            exc.add_note(f"meanwhile {failure}")  # the body's own exception goes on

    async def open(self) -> None:
        """First half of starting: checks the set-up and opens the endpoint (CREATED to OPEN).

        Raises:
            RobotStateError: the robot was opened before (a Robot runs once).
            ConfigurationError: the clock, transport or messages cannot work together.
        """
        if self._state is not RobotState.CREATED:
            raise RobotStateError(
                f"robot {self.robot_id} is {self._state}; a Robot runs once, create a new one"
            )
        loop = asyncio.get_running_loop()
        self.clock.check_loop(loop)
        transport = self.transport
        if self.clock.is_virtual and transport is not None and not transport.supports_virtual_time:
            raise ConfigurationError(
                f"robot {self.robot_id}: {type(transport).__name__} uses real sockets, which "
                "do not run on virtual time; use MemoryTransport with VirtualClock, "
                "or ScaledClock with this transport"
            )
        layers = len(self._runtimes)
        # Made before any socket: refuses a class that is no message, or two with one tag.
        codec = Codec.shared(layers, self._messages, self._max_datagram_size)
        first_id = self.clock.message_id_base(self.robot_id)
        kept = ReplyCache(keep_for=self.clock.loop_seconds(self.reply_memory))
        if transport is None:
            self._outbox.connect(codec, None, first_id, now=loop.time, replies=kept)
        else:
            endpoint = await transport.open(self.robot_id, self._reception)
            try:
                limit = min(self._max_datagram_size, endpoint.max_datagram_size)
                codec = Codec.shared(layers, self._messages, limit)
                wire = transport.wire_codec(self.robot_id, codec)
            except BaseException:
                endpoint.close()  # the socket must not outlive a robot that never started
                self._state = RobotState.STOPPED
                raise
            self._outbox.connect(wire, endpoint, first_id, now=loop.time, replies=kept)
        self._state = RobotState.OPEN

    def start(self) -> None:
        """Second half of starting: starts the clock and one task per layer (OPEN to RUNNING).

        Raises:
            RobotStateError: the robot is not open.
        """
        if self._state is not RobotState.OPEN:
            raise RobotStateError(
                f"robot {self.robot_id} is {self._state}; open() it (once) before start()"
            )
        loop = asyncio.get_running_loop()
        self.clock.start()
        self._state = RobotState.RUNNING
        clock = self.clock
        self._reception.open(loop.time, lambda: clock.id_time() + ID_SLACK)
        for runtime in self._runtimes:
            runtime.start()
        self._outbox.follow_membership(True)
        self._supervisor = loop.create_task(
            self._supervise(), name=f"cas_async robot {self.robot_id}"
        )

    async def halt(self) -> None:
        """Stops the layer tasks and waits for them; the endpoint stays open.

        Called by leaving ``async with``; a :class:`~cas_async.Swarm` halts every
        robot before closing any. Does nothing when the robot never started.
        """
        supervisor = self._supervisor
        if supervisor is None:
            return
        self.stop()
        try:
            await asyncio.shield(supervisor)
        except asyncio.CancelledError:
            # Our caller is being cancelled: still finish the shutdown, then go on cancelling.
            supervisor.cancel()
            await asyncio.wait([supervisor])
            raise
        finally:
            self._outbox.follow_membership(False)  # nothing runs that could use the news

    def close(self) -> None:
        """Closes the endpoint and fails what still waits on the robot (to STOPPED); idempotent.

        Call it after :meth:`halt`: a layer still running would find its robot gone.
        """
        if self._state is RobotState.STOPPED:
            return
        self._reception.close()
        for runtime in self._runtimes:
            runtime.close()
        self._outbox.close()
        if self._state is not RobotState.CREATED:  # it had ids: the next life goes on above
            self.clock.ids_used(self.robot_id, self._outbox.next_id())
        self._state = RobotState.STOPPED

    def take_failure(self) -> BaseException | None:
        """The layer failure that ``run()`` did not raise, once; ``None`` if there is none.

        Leaving ``async with`` raises it; code driving :meth:`halt` and :meth:`close`
        itself raises it (or attaches it to its own error) after closing.
        """
        failure, self._failure = self._failure, None
        return failure

    async def run(self) -> None:
        """Runs until every layer's ``termination_condition()`` holds, or ``stop()``.

        Starts (and afterwards stops) the robot when called outside ``async with``.

        Raises:
            LayerError: a layer raised; the other layers were stopped.
            RobotStateError: the robot is stopped, or open but not started.
        """
        if self._state is RobotState.CREATED:
            async with self:
                await self.run()
            return
        if self._state is not RobotState.RUNNING:
            raise RobotStateError(f"robot {self.robot_id} is {self._state}; a Robot runs once")
        await self._done.wait()
        outcome = self._outcome
        if outcome is not None:
            if outcome is self._failure:
                self._failure = None  # reported here: leaving the block does not raise it again
            raise outcome

    def stop(self) -> None:
        """Asks the robot to stop: ``run()`` returns and the layer tasks are cancelled.

        Safe to call from a layer and more than once.

        Raises:
            RobotStateError: the robot was never started.
        """
        if self._state in (RobotState.CREATED, RobotState.OPEN):
            raise RobotStateError(f"robot {self.robot_id} was never started")
        self._finish(None)
        self._stop_requested.set()

    async def _supervise(self) -> None:
        try:
            async with asyncio.TaskGroup() as group:
                tasks = [
                    group.create_task(
                        run_layer(runtime, self.restart),
                        name=f"cas_async {runtime.log.prefix.rstrip(': ')}",
                    )
                    for runtime in self._runtimes
                ]
                await self._stop_requested.wait()
                for task in tasks:
                    task.cancel()
        except BaseExceptionGroup as group:
            first, *others = group.exceptions
            for other in others:
                first.add_note(f"at the same time: {other}")
            # Kept apart from run()'s outcome: a failure after run() returned (or during
            # shutdown) must still surface when the robot's block is left.
            self._failure = first
            self._finish(first)

    def _finish(self, error: BaseException | None) -> None:
        if not self._done.is_set():
            self._outcome = error
            self._done.set()
        if error is not None:
            self._stop_requested.set()

    def _layer_may_be_done(self, runtime: LayerRuntime) -> None:
        """Called after a judging layer's batch: finishes ``run()`` when every judge is done.

        Only layers that override ``termination_condition`` have a say: a layer
        that merely forwards should not keep a robot running forever.
        """
        if runtime.layer.termination_condition() and all(
            judge.layer.termination_condition() for judge in self._judges
        ):
            self._finish(None)
