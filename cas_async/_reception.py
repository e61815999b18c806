"""A robot's incoming datagrams: decoded, checked, de-duplicated and routed, or refused.

:class:`Reception` is the robot's :class:`~cas_async.transport._base.DatagramSink`.
Nothing that arrives can end the robot: every datagram is either delivered to the
layer of its level or dropped and counted in ``robot.dropped`` under its reason,
checked in this order:

* ``not_running``: the robot is not running (a datagram after stop);
* ``decode.<reason>``, ``stack_mismatch``: not a valid datagram of this stack;
* ``cross_level``, ``no_such_layer``: external messages connect same levels only;
* ``from_own_id``: it claims to come from this very robot;
* ``spoofed_sender``: the transport knows who sent it (by source address, or an
  authenticated id) and the header claims someone else;
* ``unknown_sender``: it claims a robot this robot cannot reach (a reply to it
  could only fail);
* ``duplicate``, ``stale``: its id was seen before from that sender, or is too
  old to tell (see :mod:`cas_async._dedup`). A duplicate of a request already
  answered gets the kept reply again, so a requester whose reply was lost
  recovers by re-sending.

Logging is rate-limited (see :class:`~cas_async._logs.DropLog`), so a flood of
hostile datagrams cannot fill a disk.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Final

from ._dedup import DUPLICATE, ReplyCache, SenderWindows
from ._errors import DecodeError, RobotStateError, StackMismatchError, UnknownRobotError
from ._fingerprint import describe_fingerprint
from ._message import Message, MsgType
from ._types import RobotId
from ._wire_codec import WireCodec
from .transport._base import Endpoint

if TYPE_CHECKING:
    from ._robot import Robot

__all__ = ["Reception"]

_MISMATCHES_EXPLAINED: Final = 16
"""Foreign stacks whose first datagram is explained in the log; the rest are counted."""

_NEGOTIATION: Final = MsgType.NEGOTIATION


def _describe(data: object) -> str:
    """A datagram, or a message passed as an object (see :mod:`cas_async._wire_codec`), in a log."""
    if isinstance(data, bytes | bytearray | memoryview):
        return f"datagram of {len(data)} bytes"
    return repr(data)


class Reception:
    """Receives for one robot; see the module docs for what is refused and why.

    Attributes:
        senders: per sender, the message ids seen and when it was last heard.
        replies: the replies kept for requests that may be sent again.
        replies_resent: kept replies sent again to a repeated request.
    """

    __slots__ = (
        "_codec",
        "_endpoint",
        "_mismatches_seen",
        "_now",
        "_robot",
        "replies",
        "replies_resent",
        "running",
        "senders",
    )

    def __init__(self, robot: Robot) -> None:
        self._robot = robot
        self._codec: WireCodec | None = None
        self._endpoint: Endpoint | None = None
        self._now: Callable[[], float] | None = None
        self._mismatches_seen: set[int] = set()
        self.senders = SenderWindows()
        self.replies = ReplyCache()
        self.replies_resent = 0
        self.running = False  # set by the robot between start and stop

    def attach(self, codec: WireCodec, endpoint: Endpoint, now: Callable[[], float]) -> None:
        """Starts receiving with ``codec`` on ``endpoint``; ``now()`` dates each sender's news."""
        self._codec = codec
        self._endpoint = endpoint
        self._now = now

    def datagram_received(self, data: bytes, sender: RobotId | None = None) -> None:
        """Decodes, checks and routes one datagram; anything wrong is dropped and counted."""
        robot = self._robot
        codec = self._codec
        if not self.running or codec is None:
            robot._drop("not_running", f"{_describe(data)} while not running")
            return
        try:
            msg = codec.decode(data)
        except StackMismatchError as exc:
            self._refuse_stack(exc)
            return
        except DecodeError as exc:
            robot._drop(f"decode.{exc.reason}", str(exc))
            return
        level = msg.dst_layer
        claimed = msg.robot_id
        if msg.src_layer != level:
            robot._drop(
                "cross_level", f"external {msg!r}: external messages connect same levels only"
            )
        elif not 0 <= level < len(robot.layers):
            robot._drop(
                "no_such_layer", f"external {msg!r}: this robot has {len(robot.layers)} layers"
            )
        elif claimed == robot.robot_id:
            robot._drop("from_own_id", f"external {msg!r} claims to come from this robot")
        elif sender is not None and claimed != sender:
            robot._drop("spoofed_sender", f"external {msg!r} was sent by robot {sender}")
        elif sender is None and not self._endpoint.knows(claimed):  # type: ignore[union-attr]
            # A sender the transport named is one it knows; only an anonymous one is looked up.
            robot._drop("unknown_sender", f"external {msg!r} from a robot this one cannot reach")
        else:
            seen = self.senders.check(claimed, msg.msg_id, self._now())  # type: ignore[misc]
            if seen:
                self._repeated(msg, seen == DUPLICATE)
            elif not robot.layers[level]._accept_external(msg):
                # Refused by a full inbox: a copy sent again must not count as a repeat.
                self.senders.forget(claimed, msg.msg_id)

    def _repeated(self, msg: Message, duplicate: bool) -> None:
        robot = self._robot
        if not duplicate:
            robot._drop("stale", f"{msg!r} is too old to tell whether it was seen")
            return
        if msg.msg_type == _NEGOTIATION and not msg.corr_id:
            kept = self.replies.get(msg.robot_id, msg.msg_id)
            if kept is not None:
                self.send_reply(msg.robot_id, kept)
                self.replies_resent += 1
        robot._drop("duplicate", f"{msg!r} was delivered before")

    def send_reply(self, asker: RobotId, data: bytes) -> None:
        """Sends an encoded reply; an asker that left meanwhile is a dropped reply, not an error."""
        try:
            self._endpoint.send(asker, data)  # type: ignore[union-attr]
        except (UnknownRobotError, RobotStateError) as exc:
            self._robot._drop("reply_undeliverable", str(exc))

    def transport_dropped(self, reason: str, detail: str) -> None:
        """Counts what the transport lost or refused, as ``transport.<reason>``."""
        self._robot._drop(f"transport.{reason}", detail)

    def _refuse_stack(self, exc: StackMismatchError) -> None:
        # Explained once per foreign stack, for the first few stacks only: random
        # datagrams carry random fingerprints and must not fill the log or memory.
        seen = self._mismatches_seen
        explain = exc.theirs not in seen and len(seen) < _MISMATCHES_EXPLAINED
        robot = self._robot
        robot._drops.drop("stack_mismatch", str(exc), log=not explain)
        if explain:
            seen.add(exc.theirs)
            robot._log.error(
                "refusing datagrams from robot %s: its stack (%s) differs from ours (%s). "
                "Robots that exchange messages must run identical stacks: the same number of "
                "layers and the same registered messages (import the same message modules, or "
                "pass the same messages=[...] to every Robot). "
                "Further mismatches are counted and logged sparsely.",
                exc.sender,
                describe_fingerprint(exc.theirs),
                describe_fingerprint(exc.ours),
            )
