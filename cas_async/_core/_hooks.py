"""The edges of a layer's runtime: what it calls on the user's layer, and what the layer sees.

* :class:`Hooks`: the methods of the user's :class:`~cas_async.Layer` the runtime calls,
  and :func:`hook_problems`: which of a layer class's hooks it could not call so;
* :class:`RobotHandle`: what a layer sees of its robot (``self.robot``): its id,
  clock and state, and how to stop it; a layer knows nothing else of the robot
  (thesis rule 8: layers are developed in isolation);
* :class:`Detached`: the stand-in runtime of a layer not yet given to a robot;
* :class:`Overrides`: which optional hooks a layer's class overrides.
"""

from __future__ import annotations

import inspect
import reprlib
from collections.abc import Callable, Hashable
from types import FunctionType
from typing import Any, Final, NoReturn, Protocol, final
from weakref import WeakKeyDictionary

from .._errors import RobotStateError
from .._time._clock import Clock
from .._types import RobotId
from .._wire._message import Message
from ._robot_state import RobotState

__all__ = ["Detached", "Hooks", "Overrides", "RobotHandle", "hook_problems"]


class Hooks(Protocol):
    """What the runtime calls on the user's layer (see :class:`~cas_async.Layer`)."""

    @property
    def default_request_timeout(self) -> float:
        """Simulated seconds a request waits for its reply when given no timeout."""

    async def inner_process(self) -> None:
        """The layer's own work."""

    async def handle_msg(self, msg: Message) -> None:
        """An external message."""

    async def store_intra_msg(self, msg: Message) -> None:
        """An internal ACCEPT or DENY."""

    async def get_intra_msg_reply(self, msg: Message) -> Message | None:
        """The automatic reply to an internal NEGOTIATION."""

    def get_msg_reply(self, msg: Message) -> Message | None:
        """The reply to an external NEGOTIATION, given on its arrival (``None``: not now)."""

    async def on_timer(self, key: Hashable) -> None:
        """Timer ``key`` went off."""

    async def on_robot_joined(self, robot_id: RobotId) -> None:
        """Robot ``robot_id`` can now be reached."""

    async def on_robot_left(self, robot_id: RobotId) -> None:
        """Robot ``robot_id`` can no longer be reached."""

    async def on_restart(self, error: Exception) -> None:
        """Called before the layer runs again after ``error``."""

    def termination_condition(self) -> bool:
        """Whether the layer is done."""


_HOOKS: Final = tuple(
    name
    for name, member in vars(Hooks).items()
    if inspect.isfunction(member) and not name.startswith("_")
)
_ABSENT: Final = object()
_checked: WeakKeyDictionary[type[Any], tuple[str, ...]] = WeakKeyDictionary()


def hook_problems(cls: type[Any]) -> tuple[str, ...]:
    """Each hook of ``cls`` the runtime could not call as :class:`Hooks` says: one line each.

    A hook must take the arguments the runtime passes (``handle_msg(self, msg)``:
    one, positionally; defaults and ``*args`` may take more), be ``async def``
    where the runtime awaits it and a plain ``def`` where it does not
    (``get_msg_reply``, ``termination_condition``). A decorated hook is judged
    by what ``functools.wraps`` says it wraps; a hook whose signature cannot be
    read is trusted. Each line starts with the hook's name, e.g. ``handle_msg(self)
    cannot be called as Layer's async def handle_msg(self, msg: Message) -> None``.
    Checked once per class.
    """
    problems = _checked.get(cls)
    if problems is None:
        problems = tuple(
            problem for name in _HOOKS if (problem := _hook_problem(cls, name)) is not None
        )
        _checked[cls] = problems
    return problems


def _hook_problem(cls: type[Any], name: str) -> str | None:
    expected: Callable[..., Any] = getattr(Hooks, name)
    awaited = inspect.iscoroutinefunction(expected)
    wanted = f"{'async def' if awaited else 'def'} {name}{_readable(inspect.signature(expected))}"
    member = inspect.getattr_static(cls, name, _ABSENT)
    if member is _ABSENT:
        return None
    if isinstance(member, staticmethod):
        function, bound = member.__func__, 0
    elif isinstance(member, classmethod):
        function, bound = member.__func__, 1
    elif isinstance(member, FunctionType):
        function, bound = member, 1  # self
    elif callable(member):
        function, bound = member, 0
    else:
        return f"{name} is {reprlib.repr(member)}, not a method like Layer's {wanted}"
    try:
        signature = inspect.signature(function)
    except (TypeError, ValueError):  # a builtin or an extension's: nothing to read
        return None
    arguments = len(inspect.signature(expected).parameters) - 1  # without self
    try:
        signature.bind(*[None] * (bound + arguments))
    except TypeError:
        return f"{name}{_readable(signature)} cannot be called as Layer's {wanted}"
    is_async = inspect.iscoroutinefunction(inspect.unwrap(function))
    if awaited and not is_async:
        return f"{name} is a plain def, where Layer's is {wanted} (the runtime awaits it)"
    if is_async and not awaited:
        return f"{name} is async def, where Layer's is {wanted} (the runtime does not await it)"
    return None


class _Written(str):
    """An annotation as its author wrote it: shown without the quotes of a ``str``."""

    __slots__ = ()

    def __repr__(self) -> str:
        return str(self)


def _readable(signature: inspect.Signature) -> inspect.Signature:
    """``signature`` with each annotation as written: ``(self, msg: Message) -> None``."""

    def written(annotation: object) -> object:
        if annotation is inspect.Signature.empty:
            return annotation
        if isinstance(annotation, str):  # postponed (``from __future__ import annotations``)
            return _Written(annotation)
        return _Written(inspect.formatannotation(annotation))

    parameters = [
        parameter.replace(annotation=written(parameter.annotation))
        for parameter in signature.parameters.values()
    ]
    return signature.replace(
        parameters=parameters, return_annotation=written(signature.return_annotation)
    )


class RobotHandle(Protocol):
    """What a layer sees of its robot: its id, clock and state, and how to stop it."""

    @property
    def robot_id(self) -> RobotId:
        """The robot's id."""

    @property
    def clock(self) -> Clock:
        """The robot's clock."""

    @property
    def state(self) -> RobotState:
        """Where the robot is in its lifecycle."""

    def stop(self) -> None:
        """Asks the robot to stop."""

    def last_heard(self, robot_id: RobotId) -> float | None:
        """Simulated time of the latest message delivered from ``robot_id``."""

    def inbox_sizes(self) -> tuple[int, ...]:
        """Messages waiting in each layer's inbox, top first."""


@final
class Detached:
    """The runtime of a layer not yet given to a robot: every use says so."""

    __slots__ = ("_owner",)

    def __init__(self, owner: str) -> None:
        self._owner = owner

    def __getattr__(self, name: str) -> NoReturn:
        raise RobotStateError(
            f"{self._owner} is not part of a robot yet: give it to a Robot(...) first"
        )


@final
class Overrides:
    """Which optional hooks a layer's class overrides (the others are never called)."""

    __slots__ = ("answers", "inner", "membership")

    def __init__(self, *, inner: bool, answers: bool, membership: bool) -> None:
        self.inner = inner  # inner_process: runs after each batch
        self.answers = answers  # get_msg_reply: answers requests on arrival
        self.membership = membership  # on_robot_joined / on_robot_left
