"""The exceptions cas_async raises, under one root.

Hierarchy::

    CasError
    ├── ConfigurationError        a robot, clock or transport was set up wrongly
    ├── RobotStateError           an operation does not fit the robot's lifecycle
    ├── UnknownRobotError         (also LookupError) no address for a robot id
    ├── MessageDefinitionError    (also TypeError) a message class is not valid
    ├── EncodeError               (also ValueError) a message cannot be encoded
    ├── DecodeError               (also ValueError) bytes are not a valid datagram
    │   └── StackMismatchError    valid bytes from a robot with a different stack
    ├── RuleViolation             (also ValueError) a request broke a rule of the model
    ├── SimulationError           (also ValueError) a motion or simulation input is
    │                             not valid (a non-finite pose, a bad speed profile)
    ├── RequestTimeout            (also TimeoutError) no reply in time
    │   └── RobotGone             the robot asked is not, or no longer, reachable
    ├── UnexpectedReply           (also TypeError) a reply of another type than asked for
    └── LayerError                a layer raised; the original is ``__cause__``

Decoding untrusted bytes only ever raises ``DecodeError`` (or its subclass), so
one ``except DecodeError`` is enough to keep a robot alive whatever arrives.
"""

from __future__ import annotations

from typing import Final

__all__ = [
    "CasError",
    "ConfigurationError",
    "DecodeError",
    "EncodeError",
    "LayerError",
    "MessageDefinitionError",
    "RequestTimeout",
    "RobotStateError",
    "RobotGone",
    "RuleViolation",
    "SimulationError",
    "StackMismatchError",
    "UnexpectedReply",
    "UnknownRobotError",
]


class CasError(Exception):
    """Root of every exception raised by cas_async."""


class ConfigurationError(CasError):
    """A robot, clock or transport was configured in a way that cannot work."""


class RobotStateError(CasError):
    """An operation does not fit the robot's lifecycle (e.g. restart after stop)."""


class UnknownRobotError(CasError, LookupError):
    """No such robot: the transport has no address for it, or the Environment no record."""


class MessageDefinitionError(CasError, TypeError):
    """A message class cannot be used (bad field type, clashing name or tag)."""


class EncodeError(CasError, ValueError):
    """A message cannot be encoded (unsupported value, or larger than the limit)."""


class DecodeError(CasError, ValueError):
    """Bytes received are not a valid datagram.

    Attributes:
        reason: short, stable key used for drop counters (e.g. ``"wrong_type"``).
    """

    REASONS: Final = (
        "oversize",
        "malformed",
        "bad_header",
        "unknown_type",
        "wrong_arity",
        "wrong_type",
        "out_of_range",
        "stack_mismatch",
    )

    def __init__(self, message: str, reason: str = "malformed") -> None:
        super().__init__(message)
        self.reason = reason


class StackMismatchError(DecodeError):
    """A datagram from a robot whose stack differs from ours (by its fingerprint prefix).

    Attributes:
        theirs: the sender's stack fingerprint.
        ours: this robot's stack fingerprint.
    """

    def __init__(self, message: str, theirs: int, ours: int) -> None:
        super().__init__(message, "stack_mismatch")
        self.theirs = theirs
        self.ours = ours


class RuleViolation(CasError, ValueError):
    """A request broke a rule of the layered model (e.g. asked its own level).

    Plain sends that break a rule are dropped and counted; a request, which must
    return a reply, also raises this so the caller does not wait for nothing.
    """


class RequestTimeout(CasError, TimeoutError):
    """A request (NEGOTIATION) got no reply within its timeout.

    Attributes:
        peer: the robot asked (``None`` for a request to a layer of the same robot).
        attempts: how many times the request was sent.
    """

    def __init__(self, message: str, peer: int | None = None, attempts: int = 1) -> None:
        super().__init__(message)
        self.peer = peer
        self.attempts = attempts


class RobotGone(RequestTimeout):
    """The robot a request was for is not, or is no longer, reachable: it left the swarm.

    Raised as soon as the robot's transport knows: at once for a robot it does not
    know, and while waiting when the robot leaves; otherwise the request times out.
    """


class UnexpectedReply(CasError, TypeError):
    """A request was answered with a message of another class than the one asked for.

    Attributes:
        reply: the message that came back.
        expected: the class the request asked for (``reply=``).
    """

    def __init__(self, message: str, reply: object, expected: type) -> None:
        super().__init__(message)
        self.reply = reply
        self.expected = expected


class LayerError(CasError):
    """A layer raised an exception; the robot stopped.

    Attributes:
        robot_id: the robot whose layer failed.
        level: the failing layer's level (0 = top).
        layer_name: the failing layer's class name.
    """

    def __init__(self, robot_id: int, level: int, layer_name: str, cause: BaseException) -> None:
        super().__init__(
            f"robot {robot_id}, layer {level} ({layer_name}) failed: "
            f"{type(cause).__name__}: {cause}"
        )
        self.robot_id = robot_id
        self.level = level
        self.layer_name = layer_name


class SimulationError(CasError, ValueError):
    """A motion or simulation input is not valid.

    Raised for a non-finite coordinate or heading, a negative or non-finite speed,
    a minimum speed above the initial one, a non-positive turn rate, a negative
    range, a move asked of an immobile robot, or an item operation the world
    refuses (a hand-over out of reach, an item the robot does not hold). The
    message names the value. The simulation kit otherwise reuses the package's
    errors: an unknown robot id raises :class:`UnknownRobotError`, a duplicate
    robot id :class:`ConfigurationError`, and a second move started while one is
    under way :class:`RobotStateError`.
    """
