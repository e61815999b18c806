"""Decoding hostile datagrams allocates a bounded amount of memory, measured with tracemalloc.

Each worst case below is a datagram of at most ``max_size`` bytes that claims far
more than it holds, or that packs as many Python objects as its bytes allow. The
peak of traced memory during ``Codec.decode`` must stay under the documented bound,
``Codec.max_decode_bytes``, computed for a codec whose ``max_size`` is the length of
the datagram (the bound grows with the bytes a datagram actually has). Run with
``-s`` to see the peaks and the bytes allocated per datagram byte.
"""

from __future__ import annotations

import gc
import struct
import tracemalloc
from typing import Any

import msgpack
import msgspec
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cas_async import DecodeError, Message
from cas_async._wire._codec import MIN_DATAGRAM
from cas_async.transport import Codec
from tests.wire import tag_of


class LimInts(Message):
    v: list[int]


class LimText(Message):
    v: str


class LimBlob(Message):
    v: bytes


class LimBareList(Message):
    v: list  # type: ignore[type-arg]


class LimBareDict(Message):
    v: dict  # type: ignore[type-arg]


class LimTable(Message):
    v: dict[str, list[int]]


class LimArray(Message):
    v: np.ndarray  # type: ignore[type-arg]


class LimArrays(Message):
    v: list[np.ndarray]  # type: ignore[type-arg]


class LimPoint(Message):
    x: float
    y: float


class LimPath(Message):
    v: list[LimPoint]


class LimVec(msgspec.Struct):
    x: float = 0.0
    y: float = 0.0


class LimVecs(Message):
    v: list[LimVec]


CLASSES = [
    LimInts,
    LimText,
    LimBlob,
    LimBareList,
    LimBareDict,
    LimTable,
    LimArray,
    LimArrays,
    LimPath,
    LimVecs,
]
CODEC = Codec.for_stack(2, [*CLASSES, LimPoint])
MAX = CODEC.max_size
HEADER = b"".join(msgpack.packb(x) for x in (1, 7, 3, 1, 1, 0))  # msg_type, msg_id, ...


def datagram(
    cls: type[Message], raw_field: bytes, *, tag: bytes | None = None, codec: Codec = CODEC
) -> bytes:
    """A one-field datagram whose field is raw msgpack (which packb cannot make)."""
    tag = msgpack.packb(tag_of(cls)) if tag is None else tag
    return codec.fingerprint.to_bytes(4, "big") + b"\x98" + tag + raw_field + HEADER


def array_header(count: int) -> bytes:
    if count < 16:
        return bytes([0x90 + count])
    if count < 2**16:
        return b"\xdc" + struct.pack(">H", count)
    return b"\xdd" + struct.pack(">I", count)


def map_header(count: int) -> bytes:
    if count < 16:
        return bytes([0x80 + count])
    if count < 2**16:
        return b"\xde" + struct.pack(">H", count)
    return b"\xdf" + struct.pack(">I", count)


def filled(cls: type[Message], item: bytes, codec: Codec = CODEC) -> bytes:
    """The largest datagram whose field is an array of copies of ``item``."""
    count = (MAX - len(datagram(cls, b"")) - 5) // len(item)
    return datagram(cls, array_header(count) + item * count, codec=codec)


def padded(cls: type[Message], raw_field: bytes) -> bytes:
    """``raw_field`` then zeros, to the largest datagram: the bytes a liar has to spend."""
    data = datagram(cls, raw_field)
    return data + b"\x00" * (MAX - len(data))


def ndarray(dtype: str, shape: Any, data: bytes) -> bytes:
    return msgpack.packb([dtype, shape, data])


def peak_of_decode(codec: Codec, data: bytes) -> tuple[int, Message | DecodeError]:
    """Peak bytes traced while ``codec.decode(data)`` ran, and its result or error."""
    gc.collect()
    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        try:
            outcome: Message | DecodeError = codec.decode(data)
        except DecodeError as exc:
            outcome = exc
        peak = tracemalloc.get_traced_memory()[1] - before
    finally:
        tracemalloc.stop()
    return peak, outcome


def bound_for(data: bytes, classes: list[type[Message]] = CLASSES) -> int:
    """The documented bound for a datagram of this length."""
    return Codec.for_stack(2, classes, max(MIN_DATAGRAM, len(data))).max_decode_bytes


def report(data: bytes, peak: int, outcome: object) -> None:
    what = getattr(outcome, "reason", type(outcome).__name__)
    print(f"\n  {len(data):6} B  peak {peak:11,}  {peak / len(data):6.1f} B/B  {what}")


DEEP = 900  # nested below the recursion limit: all of it is read

REFUSED = [
    # Lengths the bytes cannot back.
    pytest.param(padded(LimInts, array_header(2**32 - 1)), "malformed", id="array-2**32"),
    pytest.param(padded(LimBareDict, map_header(2**32 - 1)), "malformed", id="map-2**32"),
    pytest.param(padded(LimBlob, b"\xc6\xff\xff\xff\xff"), "malformed", id="bin-4GiB"),
    pytest.param(padded(LimText, b"\xdb\xff\xff\xff\xff"), "malformed", id="str-4GiB"),
    pytest.param(padded(LimBareList, b"\x91\xc9\xff\xff\xff\xff\x05"), "malformed", id="ext-4GiB"),
    pytest.param(padded(LimBareList, array_header(256) * 1023), "wrong_type", id="open-arrays"),
    pytest.param(padded(LimBareList, array_header(65535) * 20000), "wrong_type", id="open-64Ki"),
    pytest.param(padded(LimBareDict, (map_header(65535) + b"\x00") * 9000), "wrong_type", id="o-m"),
    pytest.param(datagram(LimBareList, b"\x91" * 30000 + b"\x00"), "wrong_type", id="30000-deep"),
    # As many objects as bytes allow, in a field that does not take them.
    pytest.param(filled(LimInts, b"\x80"), "wrong_type", id="empty-maps-in-list[int]"),
    pytest.param(filled(LimInts, b"\x90"), "wrong_type", id="empty-arrays-in-list[int]"),
    pytest.param(filled(LimInts, b"\x91" * DEEP + b"\x00"), "wrong_type", id="array-chains"),
    pytest.param(filled(LimTable, b"\x80"), "wrong_type", id="empty-maps-in-dict-field"),
    pytest.param(filled(LimPath, b"\x93\x00\x00\x00"), "wrong_type", id="points-of-unknown-tag"),
    # Fields that a lying converter would allocate for.
    pytest.param(datagram(LimArray, ndarray("<f8", [10**9], b"\0" * 8)), "wrong_type", id="nd-1e9"),
    pytest.param(datagram(LimArray, ndarray("<f8", [2**64 - 1] * 32, b"")), "wrong_type", id="nd"),
    pytest.param(datagram(LimArray, ndarray("<f8", [0] * 60000, b"")), "wrong_type", id="nd-dims"),
    pytest.param(
        datagram(LimArray, ndarray("<f8", [7000], b"\0" * 60000)), "wrong_type", id="nd-short"
    ),
    # Deep values under a tag, and in error paths.
    pytest.param(
        datagram(LimInts, b"\x90", tag=b"\x91" * DEEP + b"\x00"), "unknown_type", id="deep-tag"
    ),
    pytest.param(
        datagram(LimBareDict, b"\x81" + msgpack.packb("k" * 30000) + b"\x81\xa0" * 450 + b"\xc1"),
        "malformed",
        id="deep-map-under-a-30KB-key",
    ),
]


@pytest.mark.parametrize(("data", "reason"), REFUSED)
def test_a_hostile_datagram_is_refused_within_the_memory_bound(data: bytes, reason: str) -> None:
    assert len(data) <= MAX
    peak, outcome = peak_of_decode(CODEC, data)
    report(data, peak, outcome)
    assert isinstance(outcome, DecodeError)
    assert outcome.reason == reason
    assert len(str(outcome)) < 1000  # hostile values are quoted briefly, if at all
    assert peak <= bound_for(data)


ACCEPTED = [
    # The worst known: a container object for every byte or two of a bare field.
    pytest.param(filled(LimBareList, b"\x80"), id="empty-maps-in-bare-list"),
    pytest.param(filled(LimBareList, b"\x90"), id="empty-arrays-in-bare-list"),
    pytest.param(filled(LimBareList, b"\x81\x00" * 400 + b"\x80"), id="map-chains"),
    pytest.param(filled(LimBareList, b"\x81\xc0" * 3 + b"\x00"), id="short-map-chains"),
    pytest.param(filled(LimBareList, b"\x91" * DEEP + b"\x00"), id="array-chains"),
    pytest.param(filled(LimBareList, b"\x91\x90"), id="arrays-of-empty-arrays"),
    pytest.param(
        datagram(
            LimBareDict,
            map_header(13000) + b"".join(msgpack.packb(i) + b"\x90" for i in range(13000)),
        ),
        id="empty-arrays-in-bare-dict",
    ),
    pytest.param(filled(LimBareList, b"\xd4\x05\x00"), id="ext-values"),
    pytest.param(filled(LimBareList, b"\xa1a"), id="short-strings"),
    pytest.param(filled(LimVecs, b"\x80"), id="structs-all-defaults"),
    pytest.param(filled(LimArrays, b"\x93\xa2b1\x90\xc4\x01\x00"), id="zero-dim-ndarrays"),
    pytest.param(filled(LimPath, b"\x93" + msgpack.packb(tag_of(LimPoint)) + b"\x00\x00"), id="p"),
    pytest.param(filled(LimInts, b"\xd0\x80"), id="ints"),
    # The largest values of a kind.
    pytest.param(datagram(LimText, msgpack.packb("é" * 32000)), id="long-string"),
    pytest.param(datagram(LimBlob, msgpack.packb(b"x" * 65000)), id="bytes"),
    pytest.param(datagram(LimArray, ndarray("<f8", [8000], b"\x01" * 64000)), id="ndarray"),
]


@pytest.mark.parametrize("data", ACCEPTED)
def test_the_largest_valid_datagrams_stay_within_the_memory_bound(data: bytes) -> None:
    assert len(data) <= MAX
    peak, outcome = peak_of_decode(CODEC, data)
    report(data, peak, outcome)
    assert isinstance(outcome, Message)
    assert peak <= bound_for(data)


class ManyDefaults(msgspec.Struct):
    """A Struct a datagram can make from one byte (``{}``), however many fields it has."""

    a: list[int] = msgspec.field(default_factory=list)
    b: list[int] = msgspec.field(default_factory=list)
    c: dict[str, int] = msgspec.field(default_factory=dict)
    d: int = 0
    e: int = 0
    f: int = 0
    g: int = 0


class LimDefaults(Message):
    v: list[ManyDefaults]


def test_structs_of_many_defaults_stay_within_the_memory_bound() -> None:
    codec = Codec.for_stack(2, [LimDefaults])
    data = filled(LimDefaults, b"\x80", codec)  # [{}, {}, ...]: a ManyDefaults each
    peak, outcome = peak_of_decode(codec, data)
    report(data, peak, outcome)
    assert isinstance(outcome, LimDefaults)
    assert peak <= bound_for(data, [LimDefaults])


@pytest.mark.parametrize("size", [MIN_DATAGRAM, 1500, MAX])
def test_the_bound_is_the_documented_formula(size: int) -> None:
    assert Codec.for_stack(2, CLASSES, size).max_decode_bytes == 128 * size + 256 * 1024
    assert CODEC.max_decode_bytes < 9 * 2**20  # the default: about 8.3 MiB


# Pieces of msgpack that cost the most per byte, or lie about what follows.
TOKENS = [
    b"\x80",  # {}
    b"\x81\x00",  # {0: ...
    b"\x81\xa0",  # {"": ...
    b"\x91",  # [...
    b"\x92\x00",  # [0, ...
    b"\x9f",  # 15 items follow
    array_header(256),
    array_header(65535),
    array_header(2**32 - 1),
    map_header(65535),
    map_header(2**32 - 1),
    b"\x00",
    b"\xc0",
    b"\xc1",  # never used
    b"\xa2ab",
    b"\xa1\xff",  # bad UTF-8
    b"\xc4\x01x",
    b"\xc6\xff\xff\xff\xff",
    b"\xdb\xff\xff\xff\xff",
    b"\xd4\x05\x00",
    b"\xd6\xff\x00\x00\x00\x01",
    b"\xca\x00\x00\x00\x01",
    b"\xd0\x80",
    ndarray("<f8", [10**9], b""),
    ndarray("<f8", [1], b"\x00" * 8),
]


@st.composite
def hostile_datagrams(draw: st.DrawFn) -> bytes:
    """A datagram's start, then a random mix of tokens repeated up to ``max_size``."""
    cls = draw(st.sampled_from(CLASSES))
    body = b"".join(draw(st.lists(st.sampled_from(TOKENS), min_size=1, max_size=30)))
    room = MAX - len(datagram(cls, b""))
    repeat = draw(st.integers(1, max(1, room // len(body))))
    return datagram(cls, body * repeat)[:MAX]


@st.composite
def random_datagrams(draw: st.DrawFn) -> bytes:
    """Random bytes of up to ``max_size``, alone or after a datagram's start."""
    rng = draw(st.randoms(use_true_random=False))
    size = draw(st.sampled_from([0, 1, 16, 100, 2000, MAX // 2, MAX]))
    tail = rng.randbytes(rng.randrange(size + 1))
    if draw(st.booleans()):
        return tail
    return (datagram(draw(st.sampled_from(CLASSES)), b"")[: -len(HEADER)] + tail)[:MAX]


def check_bounded(data: bytes) -> None:
    peak, outcome = peak_of_decode(CODEC, data)  # anything but a DecodeError raises here
    if isinstance(outcome, DecodeError):
        assert outcome.reason in DecodeError.REASONS
    else:
        assert type(outcome) in CLASSES
    assert peak <= bound_for(data)


SLOW = settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


@pytest.mark.slow
@SLOW
@given(hostile_datagrams())
def test_hostile_structures_only_raise_decode_error_within_the_bound(data: bytes) -> None:
    check_bounded(data)


@pytest.mark.slow
@SLOW
@given(random_datagrams())
def test_random_bytes_only_raise_decode_error_within_the_bound(data: bytes) -> None:
    check_bounded(data)
