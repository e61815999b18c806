"""Property tests of the codec: round trips, and nothing but DecodeError from bad bytes."""

from __future__ import annotations

import math
from enum import IntEnum
from typing import Any

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from cas_async import DecodeError, Message, MsgType, StackMismatchError, message, spec_of
from cas_async._message import HEADER_FIELDS, specs_for
from cas_async.transport import Codec
from cas_async.transport import stack_fingerprint as fingerprint_of


class PropMode(IntEnum):
    STOPPED = -1
    IDLE = 0
    MOVING = 3


@message
class PropInner(Message):
    label: str
    weight: float


@message
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
    plain_map: dict  # type: ignore[type-arg]
    mode: PropMode
    modes: list[PropMode]
    array: np.ndarray  # type: ignore[type-arg]
    maybe_array: np.ndarray | None  # type: ignore[type-arg]
    inner: PropInner
    inners: list[PropInner]
    maybe_inner: PropInner | None


@message
class PropSmall(Message):
    n: int
    note: str = ""


@message
class PropNode(Message):
    x: int = 0


@message
class PropTree(PropNode):
    child: PropNode | None = None
    keyed: dict[tuple[int, str], float] | None = None


@message
class PropArray(Message):
    v: np.ndarray  # type: ignore[type-arg]


@message
class PropPlain(Message):
    v: list  # type: ignore[type-arg]


@message
class PropPlainMap(Message):
    v: dict  # type: ignore[type-arg]


@message
class PropListKeys(Message):
    v: dict[list[int], int]


@message
class PropChoice(Message):
    v: int | str | None


# Single-field messages let random fields reach one converter every time.
ACCEPTED = (
    PropAll,
    PropInner,
    PropSmall,
    PropNode,
    PropTree,
    PropArray,
    PropPlain,
    PropPlainMap,
    PropListKeys,
    PropChoice,
)
SPECS = specs_for(ACCEPTED)
CODEC = Codec(SPECS, fingerprint_of(4, SPECS))
BIG_CODEC = Codec(SPECS, CODEC.fingerprint, max_size=2**22)  # round trips are not about size
TYPE_IDS = [spec.type_id for spec in SPECS.values()]

# --- strategies of valid messages ----------------------------------------------------------

ints64 = st.integers(-(2**63), 2**64 - 1)
ids64 = st.integers(0, 2**64 - 1)  # message ids and corr_id: never negative on the wire
floats = st.floats(allow_nan=True, allow_infinity=True)
small_text = st.text(max_size=12)
small_bytes = st.binary(max_size=12)

plain_keys = st.none() | st.booleans() | ints64 | st.floats(allow_nan=False) | small_text
plain_values = st.recursive(
    st.none() | st.booleans() | ints64 | floats | small_text | small_bytes,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(plain_keys, inner, max_size=4),
    max_leaves=12,
)

ARRAY_DTYPES = [
    "?",
    "i1",
    "u1",
    "<i2",
    ">u2",
    "<i4",
    ">i4",
    "<i8",
    "<u8",
    "<f2",
    "<f4",
    ">f8",
    "<f8",
    "<c8",
    ">c16",
]
arrays = hnp.arrays(
    dtype=st.sampled_from(ARRAY_DTYPES).map(np.dtype),
    shape=hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=4),
)
inners = st.builds(PropInner, label=small_text, weight=floats)
headers: dict[str, st.SearchStrategy[Any]] = {
    "msg_id": ids64,
    "msg_type": st.sampled_from(MsgType),
    "robot_id": ints64,
    "src_layer": ints64,
    "dst_layer": ints64,
    "corr_id": ids64,
}

prop_all = st.builds(
    PropAll,
    i=ints64,
    f=floats,
    b=st.booleans(),
    s=st.text(max_size=40),
    raw=st.binary(max_size=40),
    nothing=st.none(),
    maybe=st.none() | ints64,
    either=small_text | ints64,
    ints=st.lists(ints64, max_size=6),
    floats=st.lists(floats, max_size=6).map(tuple),
    pair=st.tuples(ints64, small_text),
    table=st.dictionaries(small_text, ints64, max_size=4),
    nested_map=st.dictionaries(ints64, st.lists(small_text, max_size=3), max_size=3),
    plain=st.lists(plain_values, max_size=4),
    plain_map=st.dictionaries(plain_keys, plain_values, max_size=4),
    mode=st.sampled_from(PropMode),
    modes=st.lists(st.sampled_from(PropMode), max_size=4),
    array=arrays,
    maybe_array=st.none() | arrays,
    inner=inners,
    inners=st.lists(inners, max_size=3),
    maybe_inner=st.none() | inners,
    **headers,
)
trees = st.recursive(
    st.builds(PropNode, x=ints64),
    lambda child: st.builds(
        PropTree,
        x=ints64,
        child=st.none() | child,
        keyed=st.none() | st.dictionaries(st.tuples(ints64, small_text), floats, max_size=3),
    ),
    max_leaves=6,
)
messages = st.one_of(
    prop_all,
    st.builds(PropSmall, n=ints64, note=small_text, **headers),
    st.builds(PropInner, label=small_text, weight=floats, **headers),
    trees,
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
        return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)
    if isinstance(a, list | tuple):
        return len(a) == len(b) and all(map(same, a, b))
    if isinstance(a, dict):
        return sorted(map(repr, a)) == sorted(map(repr, b)) and all(
            same(value, b[key]) for key, value in a.items()
        )
    if isinstance(a, Message):
        names = (*HEADER_FIELDS, *spec_of(type(a)).field_names)
        return all(same(getattr(a, n), getattr(b, n)) for n in names)
    return bool(a == b)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(msg=messages)
def test_decode_of_encode_is_identity(msg: Message) -> None:
    data = BIG_CODEC.encode(msg)
    decoded = BIG_CODEC.decode(data)
    assert same(decoded, msg), f"{decoded!r} != {msg!r}"
    assert BIG_CODEC.encode(decoded) == data


def test_same_sees_what_equality_does_not() -> None:
    assert same(PropSmall(1), PropSmall(1))
    assert not same(PropSmall(1), PropSmall(True))
    assert not same([1.0], (1.0,))
    assert not same(0.0, -0.0)
    assert same(math.nan, math.nan)
    assert not same(np.zeros(2, "<f8"), np.zeros(2, ">f8"))
    assert not same({1: "a"}, {True: "a"})
    assert not same(PropSmall(1, msg_id=1), PropSmall(1))


# --- strategies of malformed datagrams -----------------------------------------------------

ITEM_SIZES = {np.dtype(text).str: np.dtype(text).itemsize for text in ARRAY_DTYPES}
BAD_DTYPES = ["|O", "<U2", "|S3", "a1", "float64", "<M8[s]", "<m8", "(2,)<i4", "<i4,<i4", "V8", ""]
TREE_ID = spec_of(PropTree).type_id


@st.composite
def array_like(draw: st.DrawFn) -> tuple[Any, ...]:
    """``[dtype, shape, data]``, often with the right number of bytes so numpy gets to work."""
    dtype = draw(st.sampled_from(list(ITEM_SIZES)) | st.sampled_from(BAD_DTYPES) | st.text())
    dims = st.integers(0, 4) | st.sampled_from([-1, 2**31, 2**62, 2**64 - 1])
    shape = draw(st.lists(dims, max_size=4) | st.lists(st.integers(0, 1), max_size=40))
    count = 0 if 0 in shape else math.prod(shape)
    nbytes = count * ITEM_SIZES.get(dtype, 8)
    if not 0 <= nbytes <= 256 or draw(st.integers(0, 3)) == 0:
        nbytes = draw(st.integers(0, 40))
    return (dtype, tuple(shape), draw(st.binary(min_size=nbytes, max_size=nbytes)))


wire_leaves = st.one_of(
    st.none(),
    st.booleans(),
    ints64,
    st.integers(-3, 300),
    floats,
    st.text(max_size=8),
    st.binary(max_size=24),
    st.builds(msgpack.ExtType, st.integers(0, 127), st.binary(max_size=8)),
    st.builds(msgpack.Timestamp, st.integers(0, 2**32), st.integers(0, 999_999_999)),
    st.sampled_from(TYPE_IDS),
    array_like(),
)
hashable_wire = st.recursive(
    wire_leaves.filter(lambda v: not (isinstance(v, float) and math.isnan(v))),
    lambda inner: st.lists(inner, max_size=3).map(tuple),
    max_leaves=4,
)
wire_values = st.recursive(
    wire_leaves,
    lambda inner: st.one_of(
        st.lists(inner, max_size=5),
        st.dictionaries(hashable_wire, inner, max_size=4),
        st.tuples(st.sampled_from(TYPE_IDS), inner, inner),  # shaped like a nested message
    ),
    max_leaves=10,
)


def deep(kind: str, depth: int) -> bytes:
    """Raw msgpack nested ``depth`` times (msgpack.packb refuses to nest this deep)."""
    if kind == "array":
        return b"\x91" * depth + b"\x01"
    if kind == "map":
        return b"\x81\x01" * depth + b"\x01"
    # [PropTree id, x, child, keyed], the child being the next level.
    tree_start = b"\x94" + msgpack.packb(TREE_ID) + msgpack.packb(1)
    return tree_start * depth + b"\xc0" + b"\xc0" * depth


def deep_values(*kinds: str) -> st.SearchStrategy[bytes]:
    depths = st.sampled_from([1300, 1025, 1024, 1023, 1000, 600, 300]) | st.integers(1, 1300)
    return st.builds(deep, st.sampled_from(kinds), depths)


def array_of(items: list[bytes]) -> bytes:
    """A msgpack array of already packed items."""
    head = bytes([0x90 | len(items)]) if len(items) < 16 else b"\xdc" + len(items).to_bytes(2)
    return head + b"".join(items)


valid_datagrams = messages.map(CODEC.encode)


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


def _thaw(value: Any) -> Any:
    """Arrays as lists, so they can be edited; map keys stay tuples (lists are unhashable)."""
    if type(value) is tuple:
        return [_thaw(item) for item in value]
    if isinstance(value, dict):
        return {key: _thaw(item) for key, item in value.items()}
    return value


def _nodes(value: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Paths to every node of an unpacked msgpack value (array index or map key)."""
    found = [path]
    if isinstance(value, list):
        for i, item in enumerate(value):
            found += _nodes(item, (*path, i))
    elif isinstance(value, dict):
        for key, item in value.items():
            found += _nodes(item, (*path, key))
    return found


def _replace(value: Any, path: tuple[Any, ...], new: Any) -> Any:
    if not path:
        return new
    head, rest = path[0], path[1:]
    if isinstance(value, list):
        return [_replace(v, rest, new) if i == head else v for i, v in enumerate(value)]
    return {k: _replace(v, rest, new) if k is head else v for k, v in value.items()}


@st.composite
def donor_values(draw: st.DrawFn) -> Any:
    """Any value found inside a valid datagram: realistic, but maybe in the wrong place."""
    tree = msgpack.unpackb(draw(valid_datagrams), use_list=False, strict_map_key=False)
    value = tree
    for step in draw(st.sampled_from(_nodes(_thaw(tree)))):
        value = value[step]
    return value


# Packed field values: random structures, arrays, deep nesting...
random_fields = st.one_of(
    wire_values.map(msgpack.packb),
    array_like().map(msgpack.packb),
    deep_values("array", "map", "tree"),
)
# ...and values cut out of valid datagrams (slower to draw: each needs a whole message).
raw_fields = random_fields | donor_values().map(msgpack.packb)


@st.composite
def value_mutations(draw: st.DrawFn) -> bytes:
    """A valid datagram with one header item, field or inner value swapped for another type."""
    tree = _thaw(msgpack.unpackb(draw(valid_datagrams), use_list=False, strict_map_key=False))
    if draw(st.booleans()):
        path: tuple[Any, ...] = (draw(st.integers(0, len(tree) - 1)),)  # a header item or field
    else:
        path = draw(st.sampled_from(_nodes(tree)[1:]))  # anything, however deep
    old = tree
    for step in path:
        old = old[step]
    new = draw(wire_values.filter(lambda v: type(v) is not type(old)))
    data: bytes = msgpack.packb(_replace(tree, path, new))
    return data


@st.composite
def random_bodies(draw: st.DrawFn) -> bytes:
    """A (mostly) correct header, so the field decoders run, and random fields."""
    type_id = draw(st.sampled_from(TYPE_IDS))
    msg_type = draw(st.sampled_from(MsgType))
    head: list[Any] = [CODEC.fingerprint, type_id, *draw(st.lists(ints64, min_size=6, max_size=6))]
    head[3] = int(msg_type)
    if draw(st.integers(0, 9)) == 0:  # now and then, one bad header item
        head[draw(st.integers(0, len(head) - 1))] = draw(
            wire_leaves | st.sampled_from([float(CODEC.fingerprint), CODEC.fingerprint ^ 1])
        )
    arity = len(SPECS[type_id].field_names)
    count = draw(st.sampled_from([arity, arity, arity, max(arity - 1, 0), arity + 1]))
    fields = [draw(random_fields) for _ in range(count)]
    return array_of([msgpack.packb(item) for item in head] + fields)


def prefixed_garbage() -> st.SearchStrategy[bytes]:
    """The start of a valid datagram followed by random bytes."""
    return st.tuples(valid_datagrams, st.integers(0, 64), st.binary(max_size=64)).map(
        lambda t: t[0][: t[1]] + t[2]
    )


def decode_or_decode_error(data: bytes) -> None:
    """Decodes, allowing only DecodeError; whatever decodes must be a sound message."""
    try:
        msg = CODEC.decode(data)
    except DecodeError as exc:
        check_decode_error(exc)
    else:
        check_decoded(data, msg)


def check_decode_error(error: DecodeError) -> None:
    assert error.reason in DecodeError.REASONS
    assert str(error)
    if isinstance(error, StackMismatchError):
        assert error.reason == "stack_mismatch"
        assert error.ours == CODEC.fingerprint
        assert type(error.theirs) is int
        assert type(error.sender) is int
        assert error.theirs != CODEC.fingerprint
    else:
        assert error.reason != "stack_mismatch"


def check_decoded(data: bytes, msg: Message) -> None:
    assert type(msg) in ACCEPTED
    # Only a datagram with our exact fingerprint, a known type id and six int header
    # items decodes...
    # (Read as the codec reads it, item by item: msgpack's one-shot unpackb stops at
    # 1024 levels of nesting, where its streaming unpacker does not.)
    unpacker = msgpack.Unpacker(use_list=False, strict_map_key=False)
    unpacker.feed(data)
    row = tuple(unpacker.unpack() for _ in range(unpacker.read_array_header()))
    assert type(row[0]) is int
    assert row[0] == CODEC.fingerprint
    assert row[1] == spec_of(type(msg)).type_id
    assert all(type(item) is int for item in row[1:8])
    assert type(msg.msg_type) is MsgType
    # ...and what decodes is a normal message: it encodes again, stably.
    again = BIG_CODEC.encode(msg)
    try:
        decoded_again = BIG_CODEC.decode(again)
    except DecodeError as error:
        refused = str(error)
    else:
        refused = ""
        assert BIG_CODEC.encode(decoded_again) == again
    # The nesting guard is Python's recursion limit, so a value nested just below it can
    # fail when decoded from a deeper stack. Nothing else may differ.
    assert not refused or "nest too deeply" in refused


@pytest.mark.slow
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    data=st.one_of(
        st.binary(max_size=128),
        prefixed_garbage(),
        byte_mutations(),
        value_mutations(),
        wire_values.map(msgpack.packb),
    )
)
def test_random_and_mutated_bytes_only_raise_decode_error(data: bytes) -> None:
    decode_or_decode_error(data)


@pytest.mark.slow
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=random_bodies())
def test_random_fields_under_a_valid_header_only_raise_decode_error(data: bytes) -> None:
    decode_or_decode_error(data)


# Values aimed at one converter each (besides the random ones every field gets).
AIMED: dict[type[Message], st.SearchStrategy[bytes]] = {
    PropArray: array_like().map(msgpack.packb),
    PropPlain: st.lists(wire_values, max_size=5).map(msgpack.packb),
    PropPlainMap: st.dictionaries(hashable_wire, wire_values, max_size=5).map(msgpack.packb),
    PropListKeys: st.dictionaries(hashable_wire, wire_leaves, max_size=4).map(msgpack.packb),
    PropChoice: wire_leaves.map(msgpack.packb),
    PropTree: st.tuples(st.sampled_from(TYPE_IDS), wire_leaves, wire_values, wire_values).map(
        msgpack.packb
    ),
}


@pytest.mark.slow
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), cls=st.sampled_from(list(AIMED)))
def test_any_value_in_a_field_only_raises_decode_error(
    data: st.DataObject, cls: type[Message]
) -> None:
    field = data.draw(AIMED[cls] | raw_fields, label="field")
    fields = [field] if cls is not PropTree else [msgpack.packb(1), field, msgpack.packb(None)]
    head = [CODEC.fingerprint, spec_of(cls).type_id, 1, int(MsgType.ACCEPT), 2, 0, 0, 0]
    decode_or_decode_error(array_of([msgpack.packb(item) for item in head] + fields))


@settings(max_examples=100, deadline=None)
@given(
    target=st.sampled_from([(PropPlain, "array"), (PropPlainMap, "map"), (PropTree, "tree")]),
    depth=st.integers(1, 1300),
)
def test_nesting_of_any_depth_only_raises_decode_error(
    target: tuple[type[Message], str], depth: int
) -> None:
    cls, kind = target
    fields = [deep(kind, depth)]
    if cls is PropTree:
        fields = [msgpack.packb(1), *fields, msgpack.packb(None)]
    head = [CODEC.fingerprint, spec_of(cls).type_id, 1, int(MsgType.ACCEPT), 2, 0, 0, 0]
    decode_or_decode_error(array_of([msgpack.packb(item) for item in head] + fields))


@pytest.mark.parametrize("cut", range(0, 40, 3), ids=lambda n: f"cut-{n}")
def test_every_truncation_of_a_datagram_is_a_decode_error(cut: int) -> None:
    data = CODEC.encode(PropSmall(12345, "a note long enough", msg_id=2**40))
    assert cut < len(data)
    with pytest.raises(DecodeError) as caught:
        CODEC.decode(data[:cut])
    assert caught.value.reason in {"malformed", "bad_header"}
