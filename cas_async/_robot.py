"""``Robot``: an ordered stack of layers, its transport endpoint, and their lifecycle.

The thesis's RobotArchitecture/RobotImplementation with ConnectLayers, StartProcess
and EndProcess::

    robot = Robot(robot_id=3, layers=[Top(), Middle(), Bottom()], transport=..., clock=...)
    async with robot:          # opens the endpoint, starts one task per layer
        await robot.run()      # until every termination_condition() holds
    # leaving the block cancels the layer tasks and closes the endpoint

The layer tasks live in an ``asyncio.TaskGroup`` owned by a supervisor task, so the
code that embeds a robot is never cancelled by it: when a layer raises, its siblings
are cancelled and ``run()`` (or leaving the ``async with``) raises
:class:`~cas_async._errors.LayerError` naming the robot and layer, with the original
exception as ``__cause__``.
"""

from __future__ import annotations

import asyncio
import copy
import enum
import itertools
from collections.abc import Iterable, Sequence
from types import TracebackType
from typing import final

from ._channel import DEFAULT_QUEUE_LIMIT
from ._clock import Clock, ScaledClock
from ._codec import DEFAULT_MAX_DATAGRAM, MIN_DATAGRAM, Codec
from ._counters import LayerCounters
from ._errors import (
    ConfigurationError,
    LayerError,
    RobotStateError,
    UnknownRobotError,
)
from ._fingerprint import stack_fingerprint
from ._layer import Layer
from ._logs import DropLog, logger_for
from ._message import Message, specs_for
from ._reception import Reception
from ._supervision import RestartPolicy, run_layer
from ._types import Address, RobotId
from ._wire_codec import PassThrough, WireCodec
from .transport._base import Endpoint, Transport
from .transport._unconnected import Unconnected

__all__ = ["Robot", "RobotState"]


class RobotState(enum.Enum):
    """Where a robot is in its (one-way) lifecycle."""

    CREATED = "created"
    RUNNING = "running"
    STOPPED = "stopped"

    def __str__(self) -> str:
        return self.value


@final
class Robot:
    """A robot: layers (index 0 = top), an optional transport, and a clock.

    Args:
        robot_id: unique in the swarm.
        layers: the stack, top first; each layer instance belongs to one robot.
        transport: how external messages travel; without one, ``send`` raises.
        clock: simulated time; real time (``ScaledClock(1.0)``) by default.
        messages: the message classes this robot's stack uses; they define the
            stack fingerprint. Default: every registered message. Pass it when one
            process holds messages of several applications (e.g. a test session).
        max_datagram_size: largest datagram encoded or accepted (also capped by the
            transport's own limit).
        queue_limit: pending messages per layer at which the queue is full: external
            messages are then dropped and counted, and a layer sending internal
            messages to it waits until it has drained to half (internal messages
            are never dropped).
        restart: restart a layer that raises, within these limits, instead of
            stopping the robot (see :mod:`cas_async._supervision`).
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
    ) -> None:
        if type(robot_id) is not int:
            raise ConfigurationError(f"robot_id must be an int, got {robot_id!r}")
        self.robot_id = robot_id
        self.layers: tuple[Layer, ...] = tuple(layers)
        if not self.layers:
            raise ConfigurationError(f"robot {robot_id}: a robot needs at least one layer")
        if max_datagram_size < MIN_DATAGRAM or queue_limit < 1:
            raise ConfigurationError(
                f"robot {robot_id}: max_datagram_size must be at least {MIN_DATAGRAM} bytes "
                f"and queue_limit at least 1 (got {max_datagram_size}, {queue_limit})"
            )
        self.transport = transport
        self.clock: Clock = clock if clock is not None else ScaledClock(1.0)
        self.queue_limit = queue_limit
        self.restart = restart
        self._messages = None if messages is None else tuple(messages)
        self._max_datagram_size = max_datagram_size
        self._ids = itertools.count(1)
        self._log = logger_for(robot_id)
        self._drops = DropLog(self._log)
        self._state = RobotState.CREATED
        self._endpoint: Endpoint = Unconnected(robot_id)
        self._codec: WireCodec | None = None
        self._passes_objects = False  # whether receivers get the very objects sent (wire_codec.py)
        self._supervisor: asyncio.Task[None] | None = None
        self._finished: asyncio.Future[None] | None = None
        self._stop_requested: asyncio.Event | None = None
        self._failure: BaseException | None = None
        self._error_reported = False
        self._connect_layers()
        self._reception = Reception(self)
        self._judges = [layer for layer in self.layers if layer._has_termination_condition()]

    def _connect_layers(self) -> None:
        """Thesis ConnectLayers: levels by list order, each layer knows its neighbours."""
        for level, layer in enumerate(self.layers):
            if not isinstance(layer, Layer):
                raise ConfigurationError(
                    f"robot {self.robot_id}: layer {level} is {layer!r}, not a Layer instance"
                )
            if layer._robot is not None:
                raise ConfigurationError(
                    f"robot {self.robot_id}: {type(layer).__name__} at level {level} already "
                    f"belongs to robot {layer._robot.robot_id}; create one layer instance per robot"
                )
            name = type(layer).__name__
            layer._attach(self, level, logger_for(self.robot_id, name, level))
        for upper, lower in itertools.pairwise(self.layers):
            upper._below = lower
            lower._above = upper

    # -- introspection -----------------------------------------------------------------

    @property
    def state(self) -> RobotState:
        """CREATED, RUNNING or STOPPED."""
        return self._state

    @property
    def fingerprint(self) -> int:
        """This robot's stack fingerprint (known once started)."""
        if self._codec is None:
            raise RobotStateError(f"robot {self.robot_id} has no fingerprint until it starts")
        return self._codec.fingerprint

    @property
    def address(self) -> Address | None:
        """Where other robots reach this one, once started with a transport."""
        return self._endpoint.address

    @property
    def dropped(self) -> dict[str, int]:
        """Messages dropped so far, by reason."""
        return dict(self._drops.counts)

    def counters(self) -> dict[str, int]:
        """Message counters summed over the layers, ``replies_resent`` and ``dropped.<reason>``.

        ``replies_resent`` counts kept replies sent again to a repeated request.
        """
        total = LayerCounters()
        for layer in self.layers:
            for name, value in layer.counters.as_dict().items():
                setattr(total, name, getattr(total, name) + value)
        counts = total.as_dict()
        counts["replies_resent"] = self._reception.replies_resent
        counts.update({f"dropped.{reason}": n for reason, n in sorted(self._drops.counts.items())})
        return counts

    def message_counts(self) -> dict[str, dict[str, int]]:
        """Messages this robot's layers sent, by class name, internal and external.

        Returns ``{"internal": {name: n}, "external": {name: n}}``. Forwarding is not
        counted again; a broadcast counts once per recipient.
        """
        internal: dict[str, int] = {}
        external: dict[str, int] = {}
        for layer in self.layers:
            for split, into in (
                (layer.counters.internal_by_type, internal),
                (layer.counters.external_by_type, external),
            ):
                for cls, n in split.items():
                    into[cls.__name__] = into.get(cls.__name__, 0) + n
        return {"internal": internal, "external": external}

    def __repr__(self) -> str:
        names = ", ".join(type(layer).__name__ for layer in self.layers)
        return f"Robot({self.robot_id}, [{names}], {self._state})"

    # -- lifecycle ---------------------------------------------------------------------

    async def __aenter__(self) -> Robot:
        """StartProcess: opens the endpoint and starts one task per layer."""
        await self._open()
        self._start()
        return self

    async def _open(self) -> None:
        """First half of starting: checks the set-up and opens the endpoint.

        A :class:`~cas_async._swarm.Swarm` opens every robot before starting any, so
        no layer sends to a robot whose endpoint does not exist yet.
        """
        if self._state is not RobotState.CREATED or self._codec is not None:
            raise RobotStateError(
                f"robot {self.robot_id} is {self._state}; a Robot runs once, create a new one"
            )
        loop = asyncio.get_running_loop()
        self.clock.check_loop(loop)
        if (
            self.clock.is_virtual
            and self.transport is not None
            and not self.transport.supports_virtual_time
        ):
            raise ConfigurationError(
                f"robot {self.robot_id}: {type(self.transport).__name__} uses real sockets, which "
                "do not run on virtual time; use MemoryTransport with VirtualClock, "
                "or ScaledClock with this transport"
            )
        specs = specs_for(self._messages)
        fingerprint = stack_fingerprint(len(self.layers), specs)
        # Ids only grow, also across restarts of this robot: receivers tell a
        # re-sent or duplicated message from a new one by (robot id, message id).
        self._ids = itertools.count(self.clock.message_id_base())
        if self.transport is not None:
            self._endpoint = await self.transport.open(self.robot_id, self._reception)
        limit = min(self._max_datagram_size, self._endpoint.max_datagram_size)
        try:
            codec = Codec(specs, fingerprint, limit)
            self._codec = (
                codec if self.transport is None else self.transport.wire_codec(self.robot_id, codec)
            )
        except BaseException:
            self._close()  # the socket must not outlive a robot that never started
            raise
        self._passes_objects = isinstance(self._codec, PassThrough)
        self._reception.attach(self._codec, self._endpoint, loop.time)

    def _start(self) -> None:
        """Second half of starting: starts the clock and one task per layer."""
        loop = asyncio.get_running_loop()
        self.clock.start()
        self._finished = loop.create_future()
        self._stop_requested = asyncio.Event()
        self._state = RobotState.RUNNING
        self._reception.running = True
        for layer in self.layers:
            layer._live = True
        self._supervisor = loop.create_task(
            self._supervise(), name=f"cas_async robot {self.robot_id}"
        )

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        """EndProcess: cancels the layer tasks, waits for them, closes the endpoint.

        Raises:
            LayerError: a layer failed and ``run()`` did not already raise it.
        """
        if self._state is not RobotState.RUNNING:
            return
        try:
            await self._halt()
        finally:
            self._close()
        self._raise_unreported(exc)

    async def _halt(self) -> None:
        """Stops the layer tasks and waits for them; the endpoint stays open.

        A :class:`~cas_async._swarm.Swarm` halts every robot before closing any, so
        no robot still running sends to one that is gone.
        """
        self.stop()
        supervisor = self._supervisor
        assert supervisor is not None
        try:
            await asyncio.shield(supervisor)
        except asyncio.CancelledError:
            # Our caller is being cancelled: still finish the shutdown, then go on cancelling.
            supervisor.cancel()
            await asyncio.wait([supervisor])
            raise

    def _raise_unreported(self, exc: BaseException | None) -> None:
        """Raises a layer failure that ``run()`` did not raise; notes it on ``exc`` if any."""
        error = self._error()
        if error is None or self._error_reported:
            return
        self._error_reported = True
        if exc is None:
            raise error
        exc.add_note(f"meanwhile {error}")  # the body's own exception goes on

    def _close(self) -> None:
        if self._state is RobotState.STOPPED:
            return
        self._reception.running = False
        for layer in self.layers:
            layer._live = False
            layer._requests.close()
            layer._cancel_wakes()
        self._endpoint.close()
        self._state = RobotState.STOPPED

    async def _supervise(self) -> None:
        try:
            async with asyncio.TaskGroup() as group:
                tasks = [
                    group.create_task(
                        run_layer(self, layer, self.restart),
                        name=f"cas_async {layer.log.prefix.rstrip(': ')}",
                    )
                    for layer in self.layers
                ]
                assert self._stop_requested is not None
                await self._stop_requested.wait()
                for task in tasks:
                    task.cancel()
        except BaseExceptionGroup as group:
            first, *others = group.exceptions
            for other in others:
                first.add_note(f"at the same time: {other}")
            # Kept apart from run()'s result: a failure after run() returned (or during
            # shutdown) must still surface when the robot's block is left.
            self._failure = first
            self._finish(first)

    def _finish(self, error: BaseException | None) -> None:
        finished = self._finished
        if finished is not None and not finished.done():
            if error is None:
                finished.set_result(None)
            else:
                finished.set_exception(error)
                self._stop_requested.set()  # type: ignore[union-attr]

    def _error(self) -> BaseException | None:
        finished = self._finished
        if finished is not None and finished.done() and not finished.cancelled():
            finished.exception()  # marks it retrieved: no "never retrieved" warning
        return self._failure

    async def run(self) -> None:
        """Runs until every layer's ``termination_condition()`` holds, or ``stop()``.

        Starts (and afterwards stops) the robot when called outside ``async with``.

        Raises:
            LayerError: a layer raised; the other layers were stopped.
            RobotStateError: the robot was already stopped.
        """
        if self._state is RobotState.CREATED:
            async with self:
                await self.run()
            return
        if self._state is RobotState.STOPPED:
            raise RobotStateError(f"robot {self.robot_id} is stopped; a Robot runs once")
        assert self._finished is not None
        try:
            await asyncio.shield(self._finished)
        except LayerError:
            self._error_reported = True
            raise

    def stop(self) -> None:
        """Asks the robot to stop: ``run()`` returns and the layer tasks are cancelled.

        Safe to call from a layer and more than once.

        Raises:
            RobotStateError: the robot was never started.
        """
        if self._state is RobotState.CREATED:
            raise RobotStateError(f"robot {self.robot_id} was never started")
        self._finish(None)
        if self._stop_requested is not None:
            self._stop_requested.set()

    # -- termination -------------------------------------------------------------------

    def _layer_may_be_done(self, layer: Layer) -> None:
        """Called after a layer's batch: finishes ``run()`` when every layer is done.

        Only layers that override ``termination_condition`` have a say: a layer
        that merely forwards should not keep a robot running forever.
        """
        if layer.termination_condition() and all(
            other.termination_condition() for other in self._judges
        ):
            self._finish(None)

    # -- external messages (called by layers) --------------------------------------------

    def _send_reply(self, asker: RobotId, request_id: int, response: Message) -> None:
        """Sends an external reply and keeps it, for a repetition of the request."""
        data = self._codec.encode(response)  # type: ignore[union-attr]
        reception = self._reception
        reception.replies.keep(asker, request_id, data)
        reception.send_reply(asker, data)

    def last_heard(self, robot_id: RobotId) -> float | None:
        """Simulated time of the latest message delivered from ``robot_id``, or ``None``.

        Every message accepted from it counts (a duplicate too), so a partner that
        goes quiet shows as a growing ``clock.now() - last_heard(partner)``.
        """
        heard = self._reception.senders.heard(robot_id)
        return None if heard is None else self.clock.at_loop_time(heard)

    def _broadcast(
        self, msg: Message, robots: Iterable[RobotId] | None
    ) -> tuple[int, list[RobotId]]:
        endpoint = self._endpoint
        data = self._codec.encode(msg)  # type: ignore[union-attr]
        sent, unknown = 0, []
        for robot_id in endpoint.peers() if robots is None else robots:
            if robot_id == self.robot_id:
                continue
            if sent and self._passes_objects:  # each receiver gets a message of its own
                data = self._codec.encode(copy.copy(msg))  # type: ignore[union-attr]
            try:
                endpoint.send(robot_id, data)
            except UnknownRobotError:
                unknown.append(robot_id)
            else:
                sent += 1
        return sent, unknown

    # -- DatagramSink: the transport delivers to the Reception -------------------------

    def datagram_received(self, data: bytes, sender: RobotId | None = None) -> None:
        """Handles one datagram as if the transport had delivered it (see :class:`Reception`)."""
        self._reception.datagram_received(data, sender)

    def transport_dropped(self, reason: str, detail: str) -> None:
        """Counts what the transport lost or refused."""
        self._reception.transport_dropped(reason, detail)

    def _drop(self, reason: str, detail: str) -> None:
        self._drops.drop(reason, detail)

    def _violation(self, reason: str, layer: Layer, msg: Message) -> None:
        self._drops.drop(reason, f"{type(layer).__name__}(L{layer._level}) sent {msg!r}")
