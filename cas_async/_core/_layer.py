"""The ``Layer`` base class: the hooks users write and the messaging the runtime gives.

A layer is one level of a robot's stack (thesis §4.2). Users override the hooks:

* ``inner_process()``: runs when the layer starts and after each batch of
  messages delivered to it;
* ``handle_msg(msg)``: an external message from the same level of another robot;
* ``store_intra_msg(msg)``: an internal ACCEPT/DENY message for this layer;
* ``get_intra_msg_reply(msg)``: an internal NEGOTIATION for this layer; the
  returned message travels back to the sender automatically (``None``: no reply);
* ``termination_condition()``: the robot's ``run()`` returns once it holds for
  every layer.

The runtime owns the loop (one task per layer), forwarding of internal messages
through intermediate layers, the header, and request/reply correlation (see
:mod:`cas_async._core._layer_runtime`). Rule violations are dropped, counted by reason
and logged, never delivered.

The subclass's namespace is its author's: the runtime keeps all of its state in
one attribute, ``_cas``, and every name starting with ``_cas`` is reserved.
``robot``, ``robot_id``, ``level``, ``clock``, ``log`` and ``counters`` read the
runtime but may be shadowed by an attribute of the same name; the runtime never
reads them from the layer.

Ownership: once sent, a message object belongs to the runtime, which writes its
header. Sending the same object again (or answering a request with the request
object itself) sends a copy, so a message still travelling never changes under it.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Hashable, Iterable, Sequence
from typing import Any, ClassVar, Generic, Self, TypeVar, cast, overload

from .._errors import ConfigurationError
from .._time._clock import Clock
from .._types import Level, RobotId
from .._wire._message import Message
from ._counters import LayerCounters
from ._hooks import Detached, RobotHandle, hook_problems
from ._layer_runtime import LayerRuntime
from ._logs import PrefixLogger

__all__ = ["Layer", "attach", "overrides"]

T = TypeVar("T")
R = TypeVar("R", bound=Message)


class _FromRuntime(Generic[T]):
    """A read-only view of the layer's runtime that a subclass may shadow with its own attribute.

    A non-data descriptor: an instance attribute of the same name wins, so a layer
    that sets ``self.log = []`` has its list, and the runtime is unaffected.
    """

    def __init__(self, read: Callable[[LayerRuntime], T], doc: str) -> None:
        self._read = read
        self.__doc__ = doc

    @overload
    def __get__(self, layer: None, owner: type[Any]) -> Self: ...
    @overload
    def __get__(self, layer: Layer, owner: type[Any]) -> T: ...
    def __get__(self, layer: Layer | None, owner: type[Any]) -> T | Self:
        if layer is None:
            return self
        return self._read(layer._cas)


class _RequestTimeout(float):
    """Simulated seconds a request waits for its reply when given no timeout (default 5).

    A class attribute of :class:`Layer`: set ``default_request_timeout = 2.0`` (or
    ``math.inf``) in a subclass to change it for all its requests.
    """

    __slots__ = ()

    def __repr__(self) -> str:
        return float.__repr__(self)


class Layer:
    """Base class of every layer. Subclasses override the hooks; see the module docs.

    A layer instance belongs to one robot. The runtime is attached when the robot
    is created, so subclasses may define ``__init__`` without calling ``super()``.

    Attributes:
        default_request_timeout: simulated seconds a request waits for its reply
            when given no timeout (5 s); set it in a subclass, e.g. to ``math.inf``
            for requests that wait for a physical action.
    """

    default_request_timeout: ClassVar[float] = _RequestTimeout(5.0)
    """Simulated seconds a request waits for its reply when no timeout is given."""

    _cas: LayerRuntime
    """The runtime of this layer (every name starting with ``_cas`` is reserved)."""

    def __new__(cls, *args: Any, **kwargs: Any) -> Self:
        layer = super().__new__(cls)
        # A stand-in until a robot attaches the real runtime: every use explains.
        layer._cas = cast(LayerRuntime, Detached(cls.__name__))
        return layer

    # -- hooks ---------------------------------------------------------------------

    async def inner_process(self) -> None:
        """The layer's own work: at start and after each batch of delivered messages.

        Return promptly: this layer's messages wait while it runs (replies to its
        own requests and messages passing through it do not).
        """

    async def handle_msg(self, msg: Message) -> None:
        """An external message from the same level of another robot."""

    async def store_intra_msg(self, msg: Message) -> None:
        """An internal ACCEPT or DENY message whose destination is this layer."""

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        """The automatic reply to an internal NEGOTIATION (``None``: no reply now).

        With ``None`` the asking layer goes on waiting, until this layer answers
        with :meth:`reply` or its request times out (never, with ``math.inf``).
        Such a request is noted: :meth:`~cas_async.Robot.unanswered_requests` lists it while it
        waits, the asker logs a warning once it has waited ten times its
        ``default_request_timeout``, and a scenario run reports it when it ends.
        """
        return None

    def get_msg_reply(self, msg: Message) -> Message | None:
        """The reply to an external NEGOTIATION, given the moment it arrives.

        The external twin of ``get_intra_msg_reply``, and synchronous: the runtime
        calls it on the request's arrival, *even while this layer's task awaits*
        in another hook (a request of its own, a motion), and sends what it
        returns as the reply at once. Two robots that ask each other at the same
        instant are then both answered. Return ``None`` to let the request go to
        ``handle_msg`` as usual (to answer later with ``reply()``).

        It may run between any two awaits of the layer's other hooks, so it should
        only read the layer's state (or change what it alone owns); it runs before
        the messages that arrived earlier and still wait in the inbox.
        """
        return None

    async def on_timer(self, key: Hashable) -> None:
        """Timer ``key`` (set with ``wake_at``/``wake_after``) went off.

        ``clock.now()`` is at or past its instant. ``inner_process()`` runs after
        the timers of a wake-up, as after a batch of messages.
        """

    async def on_robot_joined(self, robot_id: RobotId) -> None:
        """Robot ``robot_id`` joined the swarm: it can be reached from now on."""

    async def on_robot_left(self, robot_id: RobotId) -> None:
        """Robot ``robot_id`` left the swarm; requests waiting on it have failed (``RobotGone``)."""

    async def on_restart(self, error: Exception) -> None:
        """Called before the layer runs again after ``error``, under a restart policy.

        Reset here whatever the failure left half done; see :class:`~cas_async.RestartPolicy`.
        """

    def termination_condition(self) -> bool:
        """True when this layer is done; ``run()`` returns once every layer is.

        Layers that do not override it abstain; when no layer of a robot overrides
        it, ``run()`` lasts until ``stop()``.
        """
        return False

    # -- identity --------------------------------------------------------------------

    robot: _FromRuntime[RobotHandle] = _FromRuntime(
        lambda cas: cas.robot, "The robot this layer belongs to (its id, clock and ``stop()``)."
    )
    robot_id: _FromRuntime[RobotId] = _FromRuntime(
        lambda cas: cas.outbox.robot_id, "The id of this layer's robot."
    )
    level: _FromRuntime[Level] = _FromRuntime(
        lambda cas: cas.level, "This layer's position in the stack: 0 is the top."
    )
    clock: _FromRuntime[Clock] = _FromRuntime(
        lambda cas: cas.clock, "The robot's clock (simulated seconds)."
    )
    log: _FromRuntime[PrefixLogger] = _FromRuntime(
        lambda cas: cas.log, "A logger whose records name the robot and this layer."
    )
    counters: _FromRuntime[LayerCounters] = _FromRuntime(
        lambda cas: cas.counters, "This layer's message counters."
    )

    # -- timers ----------------------------------------------------------------------

    def wake_at(self, at: float, key: Hashable = None) -> None:
        """Sets timer ``key`` to go off at simulated instant ``at``; ``on_timer(key)`` is told.

        Arming a key again moves its timer (one timer per key, never stacked); an
        instant already past goes off at once. The event-based way to wait:
        unlike ``await self.clock.sleep()`` in a hook, the layer keeps handling
        its messages meanwhile. Timers still set when the robot stops are disarmed.
        """
        self._cas.wake_at(at, key)

    def wake_after(self, seconds: float, key: Hashable = None) -> None:
        """Sets timer ``key`` to go off ``seconds`` simulated seconds from now (see ``wake_at``)."""
        self._cas.wake_after(seconds, key)

    def cancel_wake(self, key: Hashable = None) -> bool:
        """Disarms timer ``key``; whether it was set (and had not been told yet)."""
        return self._cas.timers.cancel(key)

    def wake_due(self, key: Hashable = None) -> float | None:
        """The simulated instant timer ``key`` goes off, ``None`` when it is not set."""
        return self._cas.timers.due(key)

    # -- internal messages -----------------------------------------------------------

    def send_up(self, msg: Message) -> None:
        """Sends an internal message to the layer directly above."""
        self._cas.send_up(msg)

    def send_down(self, msg: Message) -> None:
        """Sends an internal message to the layer directly below."""
        self._cas.send_down(msg)

    def send_to_layer(self, level: Level, msg: Message) -> None:
        """Sends an internal message to any other layer of this robot.

        A farther layer is reached through every intermediate layer, each of which
        forwards it at once (and counts it) without calling its hooks.
        """
        self._cas.send_to_layer(level, msg)

    # The request methods return the runtime's coroutine itself: awaiting it is
    # awaiting the request, without a second coroutine frame on every round trip.

    @overload
    def request_down(
        self, msg: Message, *, reply: type[R], timeout: float | None = None
    ) -> Awaitable[R]: ...
    @overload
    def request_down(
        self, msg: Message, *, reply: None = None, timeout: float | None = None
    ) -> Awaitable[Message]: ...
    def request_down(
        self, msg: Message, *, reply: type[R] | None = None, timeout: float | None = None
    ) -> Awaitable[Message]:
        """Sends a NEGOTIATION to the layer below; awaiting it gives its automatic reply.

        See :meth:`request_layer`.
        """
        cas = self._cas
        return cas.request_layer(cas.level + 1, msg, timeout, reply, neighbour=True)

    @overload
    def request_up(
        self, msg: Message, *, reply: type[R], timeout: float | None = None
    ) -> Awaitable[R]: ...
    @overload
    def request_up(
        self, msg: Message, *, reply: None = None, timeout: float | None = None
    ) -> Awaitable[Message]: ...
    def request_up(
        self, msg: Message, *, reply: type[R] | None = None, timeout: float | None = None
    ) -> Awaitable[Message]:
        """Sends a NEGOTIATION to the layer above; awaiting it gives its automatic reply.

        See :meth:`request_layer`.
        """
        cas = self._cas
        return cas.request_layer(cas.level - 1, msg, timeout, reply, neighbour=True)

    @overload
    def request_layer(
        self, level: Level, msg: Message, *, reply: type[R], timeout: float | None = None
    ) -> Awaitable[R]: ...
    @overload
    def request_layer(
        self, level: Level, msg: Message, *, reply: None = None, timeout: float | None = None
    ) -> Awaitable[Message]: ...
    def request_layer(
        self,
        level: Level,
        msg: Message,
        *,
        reply: type[R] | None = None,
        timeout: float | None = None,
    ) -> Awaitable[Message]:
        """Sends a NEGOTIATION to layer ``level`` of this robot; awaiting it gives the reply.

        The reply comes from that layer's ``get_intra_msg_reply``. With ``reply``,
        it must be of that class, and type checkers know it is::

            done = await self.request_down(Move(x, y), reply=Moved)  # a Moved

        Raises:
            RequestTimeout: no reply in time.
            UnexpectedReply: the reply is not a ``reply``.
            RuleViolation: ``level`` is this layer's or outside the stack (counted too).
            RobotStateError: the robot stopped while waiting.
        """
        return self._cas.request_layer(level, msg, timeout, reply)

    # -- external messages -----------------------------------------------------------

    def send(self, robot_id: RobotId, msg: Message) -> None:
        """Sends an external message to the same level of robot ``robot_id``.

        A robot that is not reachable (it left, or never joined) is not an error:
        the message is dropped and counted as ``unknown_robot``.

        Raises:
            EncodeError: the message cannot be encoded.
            ConfigurationError: the robot has no transport.
        """
        cas = self._cas
        cas.outbox.send(cas, robot_id, msg)

    def resend(self, robot_id: RobotId, msg: Message) -> None:
        """Sends an external message this layer already sent, again and unchanged.

        It keeps its id, so the other robot handles it at most once: a repetition
        of a message it already has is dropped, and a repeated request it already
        answered is answered again with the same reply. This is how a layer that
        takes answers in ``handle_msg`` (instead of awaiting ``request()``) retries
        over a lossy network, typically from a ``wake_after`` timer.

        Raises:
            RuleViolation: ``msg`` was not sent by this layer as an external message.
        """
        self._cas.resend(robot_id, msg)

    def broadcast(self, msg: Message, robots: Iterable[RobotId] | None = None) -> None:
        """Sends one external message to the same level of several robots.

        The message is encoded once. Without ``robots``, it goes to every robot the
        transport knows besides this one; a listed robot it does not know is counted
        as ``unknown_robot``.

        Raises:
            ConfigurationError: the robot has no transport.
        """
        self._cas.broadcast(msg, robots)

    def reply(self, request: Message, response: Message) -> None:
        """Answers a request: externally to its robot, or internally to its layer.

        ``response.msg_type`` is kept (ACCEPT by default; set DENY to refuse). The
        request object itself may be sent back as the response.
        """
        self._cas.reply(request, response)

    @overload
    def request(
        self,
        robot_id: RobotId,
        msg: Message,
        *,
        reply: type[R],
        timeout: float | None = None,
        retries: int = 0,
    ) -> Awaitable[R]: ...
    @overload
    def request(
        self,
        robot_id: RobotId,
        msg: Message,
        *,
        reply: None = None,
        timeout: float | None = None,
        retries: int = 0,
    ) -> Awaitable[Message]: ...
    def request(
        self,
        robot_id: RobotId,
        msg: Message,
        *,
        reply: type[R] | None = None,
        timeout: float | None = None,
        retries: int = 0,
    ) -> Awaitable[Message]:
        """Sends a NEGOTIATION to robot ``robot_id``; awaiting it gives the reply.

        The other robot answers with its layer's ``get_msg_reply`` (on arrival), or
        from ``handle_msg`` with ``self.reply(msg, response)``. With ``retries``, a
        request left unanswered for ``timeout`` is sent again, as the same message:
        the other robot handles it once, and answers a repetition with the reply
        it already sent (which may have been lost). With ``reply``, the answer must
        be of that class, and type checkers know it is::

            pong = await self.request(2, Ping(1), reply=Pong)  # a Pong

        Args:
            robot_id: the robot to ask (same level).
            msg: the request; its ``msg_type`` becomes NEGOTIATION.
            reply: the class the answer must be of (``None``: any message).
            timeout: simulated seconds per attempt; ``default_request_timeout``
                when ``None``; ``math.inf`` waits as long as it takes.
            retries: how many times to send it again after a timeout; the whole
                request gives up after ``(retries + 1) * timeout``.

        Raises:
            RequestTimeout: no reply to any attempt (the partner went silent);
                ``attempts`` and ``peer`` say how often and whom it asked.
            RobotGone: (a ``RequestTimeout``) the robot is not reachable, or left
                while the request waited.
            UnexpectedReply: the answer is not a ``reply``.
            RuleViolation: ``robot_id`` is this robot (the drop is counted too).
            RobotStateError: the robot stopped while waiting.
            ValueError: ``retries`` is negative.
        """
        return self._cas.request(robot_id, msg, timeout, retries, reply)

    def knows(self, robot_id: RobotId) -> bool:
        """Whether robot ``robot_id`` can be reached now (it joined and has not left)."""
        return self._cas.outbox.knows(robot_id)

    def silent_for(self, robot_id: RobotId) -> float:
        """Simulated seconds since a message from robot ``robot_id`` was last delivered.

        ``math.inf`` when none ever was. A partner whose silence outlasts what the
        protocol expects (a meeting that should have happened) has gone away.
        """
        return self._cas.silent_for(robot_id)


def overrides(layer: Layer, hook: str) -> bool:
    """Whether ``layer``'s class overrides the :class:`Layer` hook named ``hook``."""
    return getattr(type(layer), hook) is not getattr(Layer, hook)


def attach(
    robot_id: RobotId,
    layers: Sequence[object],
    runtime_for: Callable[[Layer, Level], LayerRuntime],
) -> tuple[LayerRuntime, ...]:
    """Gives each layer of a new robot its runtime, made by ``runtime_for``: all or none.

    Raises:
        ConfigurationError: an item is not a :class:`Layer` instance, a layer
            already belongs to a robot, or a hook of its class could not be called
            as the runtime calls it (see :func:`~cas_async._core._hooks.hook_problems`).
    """
    checked: list[Layer] = []
    for level, layer in enumerate(layers):
        if not isinstance(layer, Layer):
            raise ConfigurationError(
                f"robot {robot_id}: layer {level} is {layer!r}, not a Layer instance"
            )
        owner = getattr(layer, "_cas", None)
        if isinstance(owner, LayerRuntime):
            raise ConfigurationError(
                f"robot {robot_id}: {type(layer).__name__} at level {level} already "
                f"belongs to robot {owner.outbox.robot_id}; "
                "create one layer instance per robot"
            )
        problems = hook_problems(type(layer))
        if problems:
            raise ConfigurationError(
                f"robot {robot_id}: {type(layer).__name__} at level {level}: " + "; ".join(problems)
            )
        checked.append(layer)
    runtimes = tuple(runtime_for(layer, level) for level, layer in enumerate(checked))
    for layer, runtime in zip(checked, runtimes, strict=True):
        layer._cas = runtime
    return runtimes
