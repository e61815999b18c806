"""A robot's incoming datagrams: decoded, checked, de-duplicated and routed, or refused.

:class:`Reception` is the robot's :class:`~cas_async._core._transport_contract.DatagramSink`.
Nothing that arrives can end the robot: every datagram is either delivered to the
layer of its level or dropped and counted in ``robot.dropped`` under its reason,
checked in this order:

* ``not_running``: the robot is not running (a datagram after stop);
* ``unknown_source``: the transport knows no robot at its source (an address that
  is no robot's, or a signature of nobody's): it speaks for nobody, whatever it
  claims, and is refused before it is decoded, so a stranger's datagrams cost a
  lookup, not a decode, and blame no robot in the log;
* ``decode.<reason>``, ``stack_mismatch``: not a valid datagram of this stack;
* ``cross_level``, ``no_such_layer``: external messages connect same levels only;
* ``from_own_id``: it claims to come from this very robot;
* ``spoofed_sender``: the header claims another robot than the one the transport
  names as its sender (by source address, or an authenticated id);
* ``future_id``: its message id is beyond any an honest sender can have used yet
  (ids count from the sender's clock, see :mod:`cas_async._core._dedup`): a forged id
  that would otherwise make the sender's real messages look old;
* ``duplicate``, ``stale``: its id was seen before from that sender, or is too
  old to tell (see :mod:`cas_async._core._dedup`). A duplicate of a request already
  answered gets the kept reply again, so a requester whose reply was lost
  recovers by re-sending.

Logging is rate-limited (see :class:`~cas_async._core._logs.DropLog`), so a flood of
hostile datagrams cannot fill a disk.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Final, final

from .._errors import DecodeError, StackMismatchError
from .._types import RobotId
from .._wire._fingerprint import describe_fingerprint
from .._wire._message import Message, MsgType
from ._dedup import FUTURE, STALE, SenderWindows
from ._layer_runtime import LayerRuntime
from ._logs import DropLog, PrefixLogger, brief
from ._outbox import Outbox

__all__ = ["Reception"]

_MISMATCHES_EXPLAINED: Final = 16
"""Foreign stacks whose first datagram is explained in the log; the rest are counted."""

_NEGOTIATION: Final = MsgType.NEGOTIATION


def _no_horizon() -> int:
    return 0


class _Described:
    """A datagram, or a message passed as an object (see :mod:`cas_async._wire._payloads`)."""

    __slots__ = ("_data",)

    def __init__(self, data: object) -> None:
        self._data = data

    def __brief__(self) -> str:
        data = self._data
        if isinstance(data, bytes | bytearray | memoryview):
            return f"datagram of {len(data)} bytes"
        return brief(data)


@final
class Reception:
    """Receives for one robot; see the module docs for what is refused and why.

    Args:
        layers: the robot's layer runtimes, top first: where messages are delivered.
        outbox: the robot's outbox: its codec, who it can reach, the kept replies.
        drops: counts (and logs) what is refused.
        log: the robot's logger (a foreign stack is explained there).
    """

    __slots__ = (
        "_decode",
        "_drops",
        "_horizon",
        "_layers",
        "_log",
        "_mismatches_seen",
        "_now",
        "_outbox",
        "_robot_id",
        "_senders",
    )

    def __init__(
        self,
        layers: Sequence[LayerRuntime],
        outbox: Outbox,
        drops: DropLog,
        log: PrefixLogger,
    ) -> None:
        self._layers = layers
        self._outbox = outbox
        self._robot_id = outbox.robot_id
        self._decode = outbox.codec.decode  # the codec of a robot that has not started
        self._drops = drops
        self._log = log
        self._now: Callable[[], float] | None = None  # set while running
        self._horizon: Callable[[], int] = _no_horizon
        self._mismatches_seen: set[int] = set()
        self._senders = SenderWindows()

    def open(self, now: Callable[[], float], horizon: Callable[[], int]) -> None:
        """Starts delivering with the outbox's codec.

        ``now()`` dates each sender's news; ``horizon()`` is the largest message id
        an honest sender can have used yet.
        """
        self._decode = self._outbox.codec.decode
        self._now = now
        self._horizon = horizon

    def close(self) -> None:
        """Stops delivering: what arrives from now on is counted as ``not_running``."""
        self._now = None

    def last_heard(self, robot_id: RobotId) -> float | None:
        """Loop time of the latest message accepted from ``robot_id``, or ``None``."""
        return self._senders.heard(robot_id)

    def datagram_received(self, data: bytes, sender: RobotId | None = None) -> None:
        """Decodes, checks and routes one datagram; anything wrong is dropped and counted."""
        now = self._now
        if now is None:
            self._drops.drop("not_running", "%s while not running", _Described(data))
            return
        if sender is None:
            self._drops.drop(
                "unknown_source", "%s from an address that is no robot's", _Described(data)
            )
            return
        try:
            msg = self._decode(data)
        except StackMismatchError as exc:
            self._refuse_stack(exc, sender)
            return
        except DecodeError as exc:
            self._drops.drop(f"decode.{exc.reason}", "%s", exc)
            return
        level = msg.dst_layer
        claimed = msg.robot_id
        layers = self._layers
        if msg.src_layer != level:
            self._drops.drop(
                "cross_level", "external %s: external messages connect same levels only", msg
            )
        elif not 0 <= level < len(layers):
            self._drops.drop(
                "no_such_layer", "external %s: this robot has %s layers", msg, len(layers)
            )
        elif claimed == self._robot_id:
            self._drops.drop("from_own_id", "external %s claims to come from this robot", msg)
        elif claimed != sender:
            # The transport names the sender (source address, signature): a claim it
            # does not confirm is refused.
            self._drops.drop("spoofed_sender", "external %s was sent by robot %s", msg, sender)
        else:
            seen = self._senders.check(claimed, msg.msg_id, now(), self._horizon)
            if seen:
                self._repeated(msg, seen)
            elif not layers[level].accept_external(msg):
                # Refused by a full inbox: a copy sent again must not count as a repeat.
                self._senders.forget(claimed, msg.msg_id)

    def _repeated(self, msg: Message, verdict: int) -> None:
        if verdict == STALE:
            self._drops.drop("stale", "%s is too old to tell whether it was seen", msg)
            return
        if verdict == FUTURE:
            self._drops.drop("future_id", "%s: no robot can have used that id yet (forged?)", msg)
            return
        if msg.msg_type == _NEGOTIATION and not msg.corr_id:
            self._outbox.resend_reply(msg.robot_id, msg.msg_id)
        self._drops.drop("duplicate", "%s was delivered before", msg)

    def robot_joined(self, robot_id: RobotId) -> None:
        """The transport can reach robot ``robot_id`` from now on: the layers are told."""
        if robot_id == self._robot_id:
            return
        for layer in self._layers:
            layer.membership_changed(robot_id, joined=True)

    def robot_left(self, robot_id: RobotId) -> None:
        """The transport can no longer reach ``robot_id``: requests to it fail, layers are told."""
        if robot_id == self._robot_id:
            return
        for layer in self._layers:
            layer.membership_changed(robot_id, joined=False)

    def transport_dropped(self, reason: str, detail: str) -> None:
        """Counts what the transport lost or refused, as ``transport.<reason>``."""
        self._drops.drop(f"transport.{reason}", "%s", detail)

    def _refuse_stack(self, exc: StackMismatchError, sender: RobotId) -> None:
        # Explained once per foreign stack, for the first few stacks only: random
        # datagrams carry random fingerprints and must not fill the log or memory.
        seen = self._mismatches_seen
        explain = exc.theirs not in seen and len(seen) < _MISMATCHES_EXPLAINED
        self._drops.drop("stack_mismatch", "%s", exc, log=not explain)
        if explain:
            seen.add(exc.theirs)
            self._log.error(
                "refusing datagrams from robot %s: its stack (%s) differs from ours (%s). "
                "Robots that exchange messages must run identical stacks: the same number of "
                "layers and the same registered messages (import the same message modules, or "
                "pass the same messages=[...] to every Robot). "
                "Further mismatches are counted and logged sparsely.",
                sender,  # as the transport knows it: the header's claim may be anyone's
                describe_fingerprint(exc.theirs),
                describe_fingerprint(exc.ours),
            )
