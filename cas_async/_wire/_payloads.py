"""What a robot's messages become on its transport: bytes, or the message objects themselves.

A robot turns each external message into what its transport carries, and back,
with its *wire codec*. Over a network that is the :class:`~cas_async._wire._codec.Codec`
(bytes). A transport that stays inside one process may instead pass the message
object itself to the receiver (``MemoryTransport(pass_objects=True)``): the robot
then uses :class:`PassThrough`, which carries the object unchanged both ways.

That saves the encoding and decoding of every message, and with them the checks
they make: the datagram size limit and whether every field can be encoded are
not checked. The receiver gets the very object that was sent, as a layer does
from its neighbour inside a robot. Ownership keeps that safe: a message belongs
to the runtime once sent, so sending it again sends a copy, and each receiver of
a broadcast gets its own (shallow) copy. Field values are shared, not copied:
a receiver that mutates a list it received should copy it first.

Robots passing objects to each other must run one stack (the same layer count
and messages), which :meth:`PassThrough.admit` checks when each one opens: there
are no bytes whose fingerprint could be refused one by one.
"""

from __future__ import annotations

from typing import Protocol

from .._errors import ConfigurationError, DecodeError
from .._types import RobotId
from ._codec import Codec
from ._fingerprint import describe_fingerprint
from ._message import Message

__all__ = ["PassThrough", "WireCodec"]


class WireCodec(Protocol):
    """What turns a robot's external messages into what its transport carries, and back."""

    @property
    def fingerprint(self) -> int:
        """The robot's stack fingerprint."""

    @property
    def passes_objects(self) -> bool:
        """Whether receivers get the very message objects sent (no bytes in between)."""

    def encode(self, msg: Message) -> bytes:
        """What the transport carries for ``msg``."""

    def decode(self, data: bytes) -> Message:
        """The message ``data`` carries; raises :class:`~cas_async._errors.DecodeError`."""


class PassThrough:
    """The wire codec of robots that pass message objects to each other (see module docs).

    One instance serves every robot of a transport; what it "encodes" is the
    message itself, typed as the transport's payload.

    Args:
        codec: the first robot's codec: its fingerprint and messages become the stack.
    """

    __slots__ = ("_classes", "_opened_by", "fingerprint")

    passes_objects = True

    def __init__(self, codec: Codec, robot_id: RobotId) -> None:
        self.fingerprint = codec.fingerprint
        self._classes = codec.message_classes
        self._opened_by = robot_id

    def admit(self, robot_id: RobotId, codec: Codec) -> PassThrough:
        """Returns this pass-through for another robot's ``codec``, if it runs the same stack.

        Raises:
            ConfigurationError: its stack differs from the first robot's.
        """
        if codec.fingerprint != self.fingerprint:
            raise ConfigurationError(
                f"robot {robot_id}: its stack ({describe_fingerprint(codec.fingerprint)}) "
                f"differs from robot {self._opened_by}'s ({describe_fingerprint(self.fingerprint)})"
                "; robots passing message objects must run identical stacks: the same "
                "number of layers and the same registered messages"
            )
        return self

    def encode(self, msg: Message) -> bytes:
        """``msg`` itself: the transport carries the object."""
        return msg  # type: ignore[return-value]  # what a pass_objects transport carries

    def decode(self, data: bytes) -> Message:
        """The message passed; anything else (bytes fed in by hand) is refused."""
        # Typed as the payload, but a message, as encode() made it.
        if isinstance(data, Message) and data.__class__ in self._classes:
            return data
        if isinstance(data, bytes | bytearray | memoryview):
            raise DecodeError(
                f"{len(data)} bytes given to a robot whose transport passes message objects",
                "malformed",
            )
        raise DecodeError(f"{type(data).__name__} is not a message of this stack", "unknown_type")
