"""Hostile datagrams for fuzzing a robot: random, cut, mutated, lying, misrouted, spoofed.

:class:`HostileDatagrams` makes datagrams of the kinds in :data:`KINDS`, from a
seeded ``random.Random`` and the victim's own :class:`~cas_async.Codec` (same
messages, same stack fingerprint), so that the mutations start from datagrams
the victim would accept::

    hostile = HostileDatagrams(Codec.for_stack(1, messages), random.Random(7), victim=1,
                               attacker=99, partner=2, levels=1)
    data = hostile.make("byte_flipped")

Every datagram claims to come from ``attacker`` (the robot at the address it is
sent from) unless its kind is about claiming someone else. Message ids of the
attacker only grow, and the generator follows the ids that mutations happen to
produce, so "valid" datagrams stay fresh for the victim's duplicate filter.
"""

from __future__ import annotations

import random
from collections.abc import Callable, Sequence
from typing import Any, Final

import msgpack

from cas_async import DecodeError, Message, MsgType
from cas_async._wire._message import message_fields
from cas_async.transport import Codec
from tests.stacks import Answer, Note, Query
from tests.wire import tag_of

__all__ = ["KINDS", "UNKNOWN_ROBOT", "HostileDatagrams", "kinds_in_turn"]

KINDS: Final = (
    "random_bytes",
    "truncated",
    "byte_flipped",
    "wrong_type_id",
    "wrong_field_types",
    "huge_lengths",
    "wrong_fingerprint",
    "wrong_level",
    "spoofed_sender",
    "valid",
)
"""What :meth:`HostileDatagrams.make` can make; "valid" ones are well-formed and honest."""

UNKNOWN_ROBOT: Final = 12345
"""A robot id nobody knows, claimed by some spoofed datagrams."""

_SAME: Final[Any] = object()
"""Default of :meth:`HostileDatagrams._wire`: the message's own fingerprint or type id."""

_MAX_RANDOM: Final = 2000
"""Longest random datagram, in bytes."""

# Values of every msgpack kind; a field gets one whose type it does not take.
_WRONG_VALUES: Final[tuple[Any, ...]] = (
    "x",
    b"x",
    1.5,
    None,
    True,
    [1, 2],
    {"a": 1},
    -1,
    2**64 - 1,
    msgpack.ExtType(5, b"x"),
)

# Headers of values whose length the bytes that follow cannot back.
_LIARS: Final = (
    b"\xdd\xff\xff\xff\xff",  # array32: 2**32 - 1 items
    b"\xdf\xff\xff\xff\xff",  # map32
    b"\xdb\xff\xff\xff\xff",  # str32: 4 GiB
    b"\xc6\xff\xff\xff\xff",  # bin32
    b"\xc9\xff\xff\xff\xff\x05",  # ext32
    b"\xdc\xff\xff",  # array16: 65535 items
    b"\xde\xff\xff",  # map16
    b"\xc4\xff",  # bin8: 255 bytes
)


class HostileDatagrams:
    """Makes hostile datagrams for one victim (see the module docs).

    Args:
        codec: a codec with the victim's messages and stack fingerprint.
        rng: the source of every random choice (seed it for reproducible runs).
        victim: the robot attacked.
        attacker: the robot id of the address the datagrams are sent from.
        partner: a robot the victim knows and trusts, impersonated by some.
        levels: how many layers the victim has.
        messages: message classes to start from; all must be in ``codec``.
    """

    def __init__(
        self,
        codec: Codec,
        rng: random.Random,
        *,
        victim: int,
        attacker: int,
        partner: int,
        levels: int,
        messages: Sequence[type[Message]] = (Note, Query, Answer),
        horizon: Callable[[], int] = lambda: 2**32,
    ) -> None:
        self._codec = codec
        self._horizon = horizon  # the largest id the victim believes (see cas_async._core._dedup)
        self._rng = rng
        self.victim = victim
        self.attacker = attacker
        self.partner = partner
        self.levels = levels
        self._messages = tuple(messages)
        self._next_id = 1
        self._makers: dict[str, Callable[[], bytes]] = {
            kind: getattr(self, f"_{kind}") for kind in KINDS
        }

    def make(self, kind: str) -> bytes:
        """One datagram of ``kind`` (one of :data:`KINDS`)."""
        return self._makers[kind]()

    # -- building blocks -----------------------------------------------------------

    def _message(self) -> Message:
        """A random message of the victim's stack, with an empty header."""
        rng = self._rng
        cls = rng.choice(self._messages)
        if cls is Note:
            text = "".join(rng.choice("abcé€😀 ") for _ in range(rng.randrange(40)))
            return Note(text, [rng.randrange(-1000, 1000) for _ in range(rng.randrange(6))])
        if cls is Query:
            return Query(rng.randrange(-(2**31), 2**31))
        if cls is Answer:
            return Answer(rng.randrange(-(2**31), 2**31), rng.randrange(self.levels))
        raise ValueError(f"no recipe for {cls.__name__}")

    def _stamp(
        self,
        msg: Message,
        *,
        robot_id: int | None = None,
        honest: bool = False,
    ) -> None:
        """Fills the header as the attacker's robot would, claiming ``robot_id`` if given.

        Unless ``honest``, one message in five claims to answer a request by a small
        message id: one the victim never made, or did make (and then it is a forged,
        late or repeated reply).
        """
        rng = self._rng
        msg.msg_id = self._fresh_id()
        msg.msg_type = rng.choice(
            (MsgType.ACCEPT, MsgType.ACCEPT, MsgType.NEGOTIATION, MsgType.DENY)
        )
        msg.robot_id = self.attacker if robot_id is None else robot_id
        msg.src_layer = msg.dst_layer = rng.randrange(self.levels)
        msg.corr_id = 0 if honest or rng.random() < 0.8 else rng.randrange(1, 1000)

    def _fresh_id(self) -> int:
        msg_id = self._next_id
        self._next_id += 1
        return msg_id

    def _encoded(self, **stamp: Any) -> bytes:
        msg = self._message()
        self._stamp(msg, **stamp)
        return self._codec.encode(msg)

    def _wire(
        self, msg: Message, fields: Sequence[Any], *, fp: Any = _SAME, tid: Any = _SAME
    ) -> bytes:
        """A datagram packed by hand: the given fields with ``msg``'s header."""
        header = (int(msg.msg_type), msg.msg_id, msg.robot_id, msg.src_layer, msg.dst_layer)
        items = [tag_of(type(msg)) if tid is _SAME else tid, *fields, *header, msg.corr_id]
        prefix = (self._codec.fingerprint if fp is _SAME else fp).to_bytes(4, "big")
        data: bytes = prefix + msgpack.packb(items, use_bin_type=True)
        return data

    def _fields(self, msg: Message) -> list[Any]:
        return [getattr(msg, name) for name in message_fields(type(msg))]

    def _follow(self, data: bytes) -> None:
        """Keeps the attacker's ids above any id a mutation made the victim accept."""
        try:
            msg = self._codec.decode(data)
        except DecodeError:
            return
        # An id beyond the victim's horizon is refused (future_id) and moves nothing.
        if msg.robot_id == self.attacker and self._next_id <= msg.msg_id <= self._horizon():
            self._next_id = msg.msg_id + 1

    # -- the kinds -------------------------------------------------------------------

    def _random_bytes(self) -> bytes:
        rng = self._rng
        return rng.randbytes(rng.randrange(_MAX_RANDOM + 1))

    def _truncated(self) -> bytes:
        data = self._encoded()
        return data[: self._rng.randrange(len(data))]

    def _byte_flipped(self) -> bytes:
        rng = self._rng
        data = bytearray(self._encoded())
        data[rng.randrange(len(data))] ^= rng.randrange(1, 256)
        flipped = bytes(data)
        self._follow(flipped)
        return flipped

    def _wrong_type_id(self) -> bytes:
        rng = self._rng
        msg = self._message()
        self._stamp(msg)
        known = {tag_of(cls) for cls in self._messages}
        tid = rng.choice((rng.randrange(2**31), -1, 2**40, "Query", 1.5, None, [1]))
        while type(tid) is int and tid in known:
            tid = rng.randrange(2**31)
        return self._wire(msg, self._fields(msg), tid=tid)

    def _wrong_field_types(self) -> bytes:
        rng = self._rng
        msg = self._message()
        self._stamp(msg)
        fields = self._fields(msg)
        roll = rng.random()
        if roll < 0.15:
            fields.append(1)  # one field too many
        elif roll < 0.3:
            fields.pop()  # one too few
        else:
            at = rng.randrange(len(fields))
            wrong = rng.choice(_WRONG_VALUES)
            while type(wrong) is type(fields[at]):  # e.g. an int for Query.value
                wrong = rng.choice(_WRONG_VALUES)
            fields[at] = wrong
        return self._wire(msg, fields)

    def _huge_lengths(self) -> bytes:
        rng = self._rng
        msg = self._message()
        self._stamp(msg)
        valid = self._wire(msg, self._fields(msg))
        filler = rng.randbytes(rng.randrange(200))
        roll = rng.random()
        prefix, body = valid[:4], valid[4:]
        if roll < 0.2:  # the datagram itself claims 2**32 - 1 items
            return prefix + b"\xdd\xff\xff\xff\xff" + body[1:] + filler
        if roll < 0.4:  # arrays nested deep, each claiming 65535 items
            depth = rng.randrange(1, 700)
            return valid + b"\xdc\xff\xff" * depth + filler
        # A lying field in place of the last one (the header would follow it).
        fields = self._fields(msg)
        head = msgpack.packb([tag_of(type(msg)), *fields[:-1]], use_bin_type=True)
        # Every message of the stack has a header and fields that fit a fixarray.
        head = bytes([0x90 + 1 + len(fields) + 6]) + head[1:]  # the count includes the liar
        return prefix + head + rng.choice(_LIARS) + filler

    def _wrong_fingerprint(self) -> bytes:
        rng = self._rng
        msg = self._message()
        self._stamp(msg)
        fp = rng.randrange(2**32)
        while fp == self._codec.fingerprint:
            fp = rng.randrange(2**32)
        return self._wire(msg, self._fields(msg), fp=fp)

    def _wrong_level(self) -> bytes:
        rng = self._rng
        msg = self._message()
        self._stamp(msg)
        if rng.random() < 0.5:  # external messages connect the same level only
            msg.dst_layer = (msg.src_layer + rng.randrange(1, 4)) % (self.levels + 3)
        else:  # a level this robot does not have
            msg.src_layer = msg.dst_layer = rng.choice((-1, self.levels, self.levels + 7, 2**40))
        return self._wire(msg, self._fields(msg))

    def _spoofed_sender(self) -> bytes:
        claimed = self._rng.choice((self.victim, UNKNOWN_ROBOT, self.partner))
        return self._encoded(robot_id=claimed)

    def _valid(self) -> bytes:
        return self._encoded(honest=True)


def kinds_in_turn(rng: random.Random, total: int, burst: int) -> list[str]:
    """The kind of each burst: every kind equally often, in a shuffled order."""
    bursts = -(-total // burst)
    turns = [KINDS[i % len(KINDS)] for i in range(bursts)]
    rng.shuffle(turns)
    return turns
