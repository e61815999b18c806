"""The edges of a layer's runtime: what it calls on the user's layer, and what the layer sees.

* :class:`Hooks`: the methods of the user's :class:`~cas_async.Layer` the runtime calls;
* :class:`RobotHandle`: what a layer sees of its robot (``self.robot``): its id,
  clock and state, and how to stop it; a layer knows nothing else of the robot
  (thesis rule 8: layers are developed in isolation);
* :class:`Detached`: the stand-in runtime of a layer not yet given to a robot;
* :class:`Overrides`: which optional hooks a layer's class overrides.
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import NoReturn, Protocol, final

from .._errors import RobotStateError
from .._time._clock import Clock
from .._types import RobotId
from .._wire._message import Message
from ._robot_state import RobotState

__all__ = ["Detached", "Hooks", "Overrides", "RobotHandle"]


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
