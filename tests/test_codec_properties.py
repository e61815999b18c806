"""Property tests of the codec: round trips, and nothing but DecodeError from any bytes."""

from __future__ import annotations

import math
from enum import IntEnum
from typing import Annotated, Any

import msgpack
import msgspec
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cas_async import DecodeError, Finite, Message, MsgType, StackMismatchError, finite
from cas_async._wire._message import HEADER_FIELDS, message_fields
from cas_async.testing import strategy_for
from cas_async.transport import Codec
from tests.wire import tag_of


class PropMode(IntEnum):
    STOPPED = -1
    IDLE = 0
    MOVING = 3


class PropVec(msgspec.Struct):
    x: float
    y: Annotated[float, Finite]


class PropInner(Message):
    label: str
    weight: Annotated[float, finite(ge=0)]


class PropLeaf(Message):
    n: int = 0


class PropAll(Message):
    """One field of every supported kind."""

    i: int
    f: float
    b: bool
    s: str
    raw: bytes
    nothing: None
    maybe: int | None
    either: str | int
    ints: list[int]
    floats: tuple[float, ...]
    pair: tuple[int, str]
    table: dict[str, int]
    nested_map: dict[int, list[str]]
    plain: list  # type: ignore[type-arg]
    mode: PropMode
    modes: list[PropMode]
    array: np.ndarray  # type: ignore[type-arg]
    vec: PropVec
    vecs: list[PropVec]
    inner: PropInner
    maybe_inner: PropInner | None
    seats: Annotated[int, msgspec.Meta(ge=1, le=8)]


class PropTree(Message):
    x: int
    child: PropInner | PropLeaf | None = None


class PropArray(Message):
    v: np.ndarray  # type: ignore[type-arg]


class PropPlain(Message):
    v: list  # type: ignore[type-arg]


class PropPlainMap(Message):
    v: dict  # type: ignore[type-arg]


class PropChoice(Message):
    v: int | str | None


ACCEPTED = (PropAll, PropInner, PropLeaf, PropTree, PropArray, PropPlain, PropPlainMap, PropChoice)
CODEC = Codec.for_stack(4, ACCEPTED)
BIG_CODEC = Codec.for_stack(4, ACCEPTED, max_size=2**22)  # round trips are not about size
PREFIX = CODEC.fingerprint.to_bytes(4, "big")
TAGS = [tag_of(cls) for cls in ACCEPTED]
HEADER = [int(MsgType.ACCEPT), 1, 2, 0, 0, 0]

# --- valid messages, drawn from their classes ---------------------------------------------------

ints64 = st.integers(-(2**63), 2**63 - 1)
headers = st.fixed_dictionaries(
    {
        "msg_type": st.sampled_from(MsgType),
        "msg_id": st.integers(1, 2**64 - 1),  # a datagram always has one
        "robot_id": ints64,
        "src_layer": ints64,
        "dst_layer": ints64,
        "corr_id": st.integers(0, 2**64 - 1),
    }
)
messages = st.builds(
    lambda msg, header: msgspec.structs.replace(msg, **header),
    st.one_of(*(strategy_for(cls) for cls in ACCEPTED)),
    headers,
)


def same(a: Any, b: Any) -> bool:
    """Equality that also checks types, compares arrays bitwise and lets NaN equal NaN."""
    if type(a) is not type(b):
        return False
    if isinstance(a, np.ndarray):
        return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()
    if isinstance(a, float):
        if math.isnan(a):
            return math.isnan(b)
        return a == b and math.copysign(1, a) == math.copysign(1, b)
    if isinstance(a, list | tuple):
        return len(a) == len(b) and all(map(same, a, b))
    if isinstance(a, dict):
        keys_alike = sorted(map(repr, a)) == sorted(map(repr, b))  # 1 and 1.0 are two keys
        return keys_alike and all(same(value, b[key]) for key, value in a.items())
    if isinstance(a, msgspec.Struct):
        return all(same(getattr(a, n), getattr(b, n)) for n in a.__struct_fields__)
    return bool(a == b)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(msg=messages)
def test_decode_of_encode_is_the_message(msg: Message) -> None:
    data = BIG_CODEC.encode(msg)
    decoded = BIG_CODEC.decode(data)
    assert same(decoded, msg), f"{decoded!r} != {msg!r}"
    assert BIG_CODEC.encode(decoded) == data


def test_same_sees_what_equality_does_not() -> None:
    assert same(PropLeaf(1), PropLeaf(1))
    assert not same(PropLeaf(1), PropLeaf(True))
    assert not same([1.0], (1.0,))
    assert not same(0.0, -0.0)
    assert same(math.nan, math.nan)
    assert not same(np.zeros(2, "<f8"), np.zeros(2, ">f8"))
    assert not same({1: "a"}, {1.0: "a"})
    assert not same(PropLeaf(1, msg_id=1), PropLeaf(1))


# --- hostile bytes -------------------------------------------------------------------------------

floats = st.floats(allow_nan=True, allow_infinity=True)
wire_leaves = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**63), 2**64 - 1),
    st.integers(-3, 300),
    floats,
    st.text(max_size=8),
    st.binary(max_size=24),
    st.builds(msgpack.ExtType, st.integers(0, 127), st.binary(max_size=8)),
    st.builds(msgpack.Timestamp, st.integers(0, 2**32), st.integers(0, 999_999_999)),
    st.sampled_from(TAGS),
    st.tuples(
        st.sampled_from(["<f8", "|u1", "<i4", "|O", "x"]),
        st.lists(st.integers(-1, 4)).map(tuple),
        st.binary(max_size=32),
    ),
)
hashable = st.recursive(
    wire_leaves.filter(lambda v: not (isinstance(v, float) and math.isnan(v))),
    lambda inner: st.lists(inner, max_size=3).map(tuple),
    max_leaves=4,
)
wire_values = st.recursive(
    wire_leaves,
    lambda inner: st.one_of(
        st.lists(inner, max_size=5),
        st.dictionaries(hashable, inner, max_size=4),
        st.tuples(st.sampled_from(TAGS), inner, inner),  # shaped like a nested message
    ),
    max_leaves=10,
)


def deep(kind: str, depth: int) -> bytes:
    """Raw msgpack nested ``depth`` times (msgpack.packb refuses to nest that deep)."""
    if kind == "array":
        return b"\x91" * depth + b"\x01"
    return b"\x81\x01" * depth + b"\x01"


def array_of(items: list[bytes]) -> bytes:
    """A msgpack array of items already packed."""
    head = bytes([0x90 | len(items)]) if len(items) < 16 else b"\xdc" + len(items).to_bytes(2)
    return head + b"".join(items)


valid_datagrams = messages.map(BIG_CODEC.encode).filter(lambda d: len(d) <= CODEC.max_size)


@st.composite
def byte_mutations(draw: st.DrawFn) -> bytes:
    """A valid datagram, truncated, with bytes flipped, replaced, inserted, removed or spliced."""
    data = bytearray(draw(valid_datagrams))
    for _ in range(draw(st.integers(1, 3))):
        where = draw(st.integers(0, len(data)))
        kind = draw(st.sampled_from(["truncate", "flip", "replace", "insert", "delete", "splice"]))
        if kind == "truncate":
            del data[where:]
        elif kind == "flip" and where < len(data):
            data[where] ^= 1 << draw(st.integers(0, 7))
        elif kind == "replace" and where < len(data):
            data[where] = draw(st.integers(0, 255))
        elif kind == "insert":
            data[where:where] = draw(st.binary(min_size=1, max_size=8))
        elif kind == "delete":
            del data[where : where + draw(st.integers(1, 8))]
        elif kind == "splice":  # the msgpack of a random structure, over random bytes
            end = draw(st.integers(where, min(len(data), where + 16)))
            data[where:end] = msgpack.packb(draw(wire_values))
    return bytes(data)


@st.composite
def value_mutations(draw: st.DrawFn) -> bytes:
    """A valid datagram with one item of its top array (tag, field, header) replaced."""
    items = msgpack.unpackb(draw(valid_datagrams)[4:], strict_map_key=False)
    where = draw(st.integers(0, len(items) - 1))
    items[where] = draw(wire_values.filter(lambda v: type(v) is not type(items[where])))
    return PREFIX + msgpack.packb(items)


def prefixed_garbage() -> st.SearchStrategy[bytes]:
    """The start of a valid datagram followed by random bytes."""
    return st.tuples(valid_datagrams, st.integers(0, 64), st.binary(max_size=64)).map(
        lambda t: t[0][: t[1]] + t[2]
    )


def outcome_of(data: bytes) -> Message | DecodeError:
    """What decoding ``data`` gives: a message, or the DecodeError (anything else raises)."""
    try:
        return CODEC.decode(data)
    except DecodeError as error:
        return error


def decode_or_decode_error(data: bytes) -> None:
    """Decodes, allowing only DecodeError; whatever decodes must be a sound message."""
    msg = outcome_of(data)
    if isinstance(msg, DecodeError):
        assert msg.reason in DecodeError.REASONS
        assert 0 < len(str(msg)) < 1000  # hostile values are quoted briefly, if at all
        if isinstance(msg, StackMismatchError):
            assert msg.ours == CODEC.fingerprint != msg.theirs
        else:
            assert msg.reason != "stack_mismatch"
        return
    # Only a datagram with our fingerprint, a known tag and a header decodes...
    assert data[:4] == PREFIX
    assert type(msg) in ACCEPTED
    assert type(msg.msg_type) is MsgType
    assert msg.msg_id > 0
    assert msg.corr_id >= 0
    assert [type(getattr(msg, name)) for name in HEADER_FIELDS[2:]] == [int] * 4
    # ...and what decodes is a normal message: it encodes again, and stably.
    again = BIG_CODEC.encode(msg)
    assert BIG_CODEC.encode(BIG_CODEC.decode(again)) == again


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    data=st.one_of(
        st.binary(max_size=128),
        st.binary(max_size=128).map(lambda tail: PREFIX + tail),
        prefixed_garbage(),
        byte_mutations(),
        value_mutations(),
        wire_values.map(lambda value: PREFIX + msgpack.packb(value)),
    )
)
@pytest.mark.slow  # a few seconds: the fast suite stays under 2 minutes
def test_random_and_mutated_bytes_only_raise_decode_error(data: bytes) -> None:
    decode_or_decode_error(data)


# Packed field values: random structures, deep nesting, values cut out of valid datagrams.
random_fields = st.one_of(
    wire_values.map(msgpack.packb),
    st.builds(deep, st.sampled_from(["array", "map"]), st.integers(1, 1300)),
)


@st.composite
def random_bodies(draw: st.DrawFn) -> bytes:
    """A known tag, random fields, and a header valid or (now and then) not."""
    cls = draw(st.sampled_from(ACCEPTED))
    arity = len(message_fields(cls))
    count = draw(st.sampled_from([arity, arity, arity, max(arity - 1, 0), arity + 1]))
    fields = [draw(random_fields) for _ in range(count)]
    header = list(HEADER)
    if draw(st.integers(0, 9)) == 0:
        header[draw(st.integers(0, 5))] = draw(wire_leaves)
    items = [msgpack.packb(tag_of(cls)), *fields, *map(msgpack.packb, header)]
    return PREFIX + array_of(items)


@pytest.mark.slow  # a few seconds: the fast suite stays under 2 minutes
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=random_bodies())
def test_random_fields_under_a_valid_header_only_raise_decode_error(data: bytes) -> None:
    decode_or_decode_error(data)


# Values aimed at one field each, besides the random ones every field gets.
AIMED: dict[type[Message], st.SearchStrategy[Any]] = {
    PropArray: wire_leaves,
    PropPlain: st.lists(wire_values, max_size=5),
    PropPlainMap: st.dictionaries(hashable, wire_values, max_size=5),
    PropChoice: wire_leaves,
    PropTree: st.tuples(st.sampled_from(TAGS), wire_leaves, wire_values),
}


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), cls=st.sampled_from(list(AIMED)))
def test_any_value_in_a_field_only_raises_decode_error(
    data: st.DataObject, cls: type[Message]
) -> None:
    field = data.draw(AIMED[cls].map(msgpack.packb) | random_fields, label="field")
    fields = [field] if cls is not PropTree else [msgpack.packb(1), field]
    items = [msgpack.packb(tag_of(cls)), *fields, *map(msgpack.packb, HEADER)]
    decode_or_decode_error(PREFIX + array_of(items))


@settings(max_examples=100, deadline=None)
@given(
    target=st.sampled_from([(PropPlain, "array"), (PropPlainMap, "map")]),
    depth=st.integers(1, 5000),
)
def test_nesting_of_any_depth_only_raises_decode_error(
    target: tuple[type[Message], str], depth: int
) -> None:
    cls, kind = target
    items = [msgpack.packb(tag_of(cls)), deep(kind, depth), *map(msgpack.packb, HEADER)]
    decode_or_decode_error(PREFIX + array_of(items))


VALID = CODEC.encode(PropTree(12345, PropInner("a note long enough", 0.5), msg_id=2**40))


@pytest.mark.parametrize("cut", range(len(VALID)), ids=lambda n: f"cut-{n}")
def test_every_truncation_of_a_datagram_is_a_decode_error(cut: int) -> None:
    with pytest.raises(DecodeError) as caught:
        CODEC.decode(VALID[:cut])
    assert caught.value.reason in {"malformed", "bad_header"}
    assert CODEC.decode(VALID) == PropTree(
        12345, PropInner("a note long enough", 0.5), msg_id=2**40
    )
