"""Decoding hostile datagrams allocates a bounded amount of memory, measured with tracemalloc.

Each worst case below is a datagram of at most ``max_size`` bytes that claims far
more than it holds, or that packs as many Python objects as bytes allow. The peak
of traced memory during ``Codec.decode`` must stay under the documented bound,
``Codec.max_decode_bytes``, computed for a codec whose ``max_size`` is the length
of the datagram (the bound grows with the bytes a datagram actually has). Run with
``-s`` to see the peaks.
"""

from __future__ import annotations

import gc
import struct
import tracemalloc
from typing import Any

import msgpack
import numpy as np
import pytest
from cas_async._datagram import MAX_NESTING
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cas_async import DecodeError, Message, MsgType, message, spec_of
from cas_async._codec import MIN_DATAGRAM
from cas_async._message import specs_for
from cas_async.transport import Codec, stack_fingerprint


@message
class LimInts(Message):
    v: list[int]


@message
class LimText(Message):
    v: str


@message
class LimBlob(Message):
    v: bytes


@message
class LimBareList(Message):
    v: list  # type: ignore[type-arg]


@message
class LimBareDict(Message):
    v: dict  # type: ignore[type-arg]


@message
class LimTable(Message):
    v: dict[str, list[int]]


@message
class LimArray(Message):
    v: np.ndarray  # type: ignore[type-arg]


@message
class LimPoint(Message):
    x: float
    y: float


@message
class LimPath(Message):
    v: list[LimPoint]


SPECS = specs_for(
    [LimInts, LimText, LimBlob, LimBareList, LimBareDict, LimTable, LimArray, LimPoint, LimPath]
)
FP = stack_fingerprint(2, SPECS)
CODEC = Codec(SPECS, FP)
MAX = CODEC.max_size
HEADER = (7, int(MsgType.ACCEPT), 3, 1, 1, 0)  # msg_id, msg_type, robot_id, src, dst, corr


def head(
    cls: type[Message], *, fp: bytes | None = None, tid: bytes | None = None, ids: bytes = b""
) -> bytes:
    """The start of a one-field datagram: array header, fingerprint, type id, header.

    ``fp``, ``tid`` and ``ids`` replace the packed fingerprint, type id and first
    header fields with raw bytes.
    """
    fp = msgpack.packb(FP) if fp is None else fp
    tid = msgpack.packb(spec_of(cls).type_id) if tid is None else tid
    header = ids + b"".join(msgpack.packb(x) for x in (HEADER[1:] if ids else HEADER))
    return b"\x99" + fp + tid + header


def datagram(cls: type[Message], raw_field: bytes) -> bytes:
    """A datagram whose one field is raw msgpack bytes (which packb cannot make)."""
    return head(cls) + raw_field


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


def filled(cls: type[Message], item: bytes, *, size: int = MAX) -> bytes:
    """A datagram of about ``size`` bytes whose field is an array of copies of ``item``."""
    count = (size - len(head(cls)) - 5) // len(item)
    return datagram(cls, array_header(count) + item * count)


def filled_chains(cls: type[Message], link: bytes, end: bytes, depth: int) -> bytes:
    """An array of values nested ``depth`` deep (``link * depth + end``), as many as fit."""
    return filled(cls, link * depth + end)


def padded(cls: type[Message], raw_field: bytes) -> bytes:
    """``raw_field`` then zeros, to the largest datagram: the bytes a liar has to spend."""
    data = datagram(cls, raw_field)
    return data + b"\x00" * (MAX - len(data))


def ndarray(dtype: str, shape: Any, data: bytes) -> bytes:
    return msgpack.packb([dtype, shape, data], use_bin_type=True)


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


def bound_for(data: bytes) -> int:
    """The documented bound for a datagram of this length."""
    return Codec(SPECS, FP, max(MIN_DATAGRAM, len(data))).max_decode_bytes


DEEP = 900  # below the nesting the structure check allows (about 990), so it is all read
SHALLOW = 400  # what the converters of bare list/dict fields still take (recursion limit)

REFUSED = [
    # Lengths that the bytes cannot back.
    pytest.param(b"\xdd\xff\xff\xff\xff" + b"\x00" * 64, "malformed", id="datagram-array32-2**32"),
    pytest.param(b"\xdf\xff\xff\xff\xff" + b"\x00" * 64, "malformed", id="datagram-map32-2**32"),
    pytest.param(padded(LimInts, array_header(2**32 - 1)), "malformed", id="array32-2**32"),
    pytest.param(padded(LimBareDict, map_header(2**32 - 1)), "malformed", id="map32-2**32"),
    pytest.param(padded(LimBlob, b"\xc6\xff\xff\xff\xff"), "malformed", id="bin32-4GiB"),
    pytest.param(padded(LimBlob, b"\xc4\xff"), "malformed", id="bin8-255-of-0"),
    pytest.param(padded(LimText, b"\xdb\xff\xff\xff\xff"), "malformed", id="str32-4GiB"),
    pytest.param(padded(LimBareList, b"\xc9\xff\xff\xff\xff\x05"), "malformed", id="ext32-4GiB"),
    # Arrays nested 1023 deep, each claiming more items than the datagram holds: the
    # C unpacker reserves slots for each as it reads its header.
    pytest.param(
        padded(LimBareList, array_header(256) * 1023), "malformed", id="1023-open-arrays-of-256"
    ),
    pytest.param(
        padded(LimBareList, array_header(257) * 1023), "malformed", id="1023-open-arrays-of-257"
    ),
    pytest.param(
        padded(LimBareList, array_header(65535) * 1023), "malformed", id="1023-open-arrays-of-64Ki"
    ),
    pytest.param(
        padded(LimBareDict, (map_header(65535) + b"\x00") * 1023),
        "malformed",
        id="1023-open-maps-of-64Ki",
    ),
    pytest.param(datagram(LimBareList, b"\x91" * 1100 + b"\x00"), "malformed", id="1100-deep"),
    # The bound counts on msgpack keeping at most 1024 arrays open: 20000 would reserve
    # 42 MB from 60 KB.
    pytest.param(
        padded(LimBareList, array_header(256) * 20000), "malformed", id="20000-open-arrays-of-256"
    ),
    # As many objects as bytes allow, in a field that does not take them.
    pytest.param(filled(LimInts, b"\x80"), "wrong_type", id="empty-maps-in-list[int]"),
    pytest.param(filled_chains(LimInts, b"\x81\x00", b"\x00", DEEP), "wrong_type", id="map-chains"),
    pytest.param(filled_chains(LimInts, b"\x91", b"\x00", DEEP), "wrong_type", id="array-chains"),
    pytest.param(filled(LimInts, b"\x81\x00\x80"), "wrong_type", id="map-of-map"),
    pytest.param(filled(LimInts, b"\xd4\x05\x00"), "wrong_type", id="ext-types"),
    pytest.param(filled(LimInts, b"\xd6\xff\x00\x00\x00\x01"), "wrong_type", id="timestamps"),
    pytest.param(filled(LimInts, b"\xa2ab"), "wrong_type", id="short-strings"),
    pytest.param(filled(LimInts, b"\xa5a\xf0\x9f\x98\x80"), "wrong_type", id="wide-strings"),
    pytest.param(filled(LimInts, b"\xca\x00\x00\x00\x01"), "wrong_type", id="floats"),
    pytest.param(filled(LimInts, b"\x91\x00"), "wrong_type", id="one-item-arrays"),
    pytest.param(filled(LimTable, b"\x80"), "wrong_type", id="empty-maps-in-dict-field"),
    pytest.param(
        datagram(LimInts, array_header(300) + b"\x80" * 300), "wrong_type", id="long-array-maps"
    ),
    pytest.param(
        datagram(LimPath, array_header(16000) + b"\x93\x00\x00\x00" * 16000),
        "wrong_type",
        id="nested-messages-with-wrong-type-id",
    ),
    # Fields that a lying converter would allocate for.
    pytest.param(
        datagram(LimArray, ndarray("<f8", [10**9], b"\x00" * 8)), "wrong_type", id="shape-10**9"
    ),
    pytest.param(
        datagram(LimArray, ndarray("<f8", [2**64 - 1] * 32, b"")), "wrong_type", id="shape-32-dims"
    ),
    pytest.param(
        datagram(LimArray, ndarray("<f8", [0, 2**62, 2**62], b"")), "wrong_type", id="shape-0-huge"
    ),
    pytest.param(
        datagram(LimArray, ndarray("<f8", [7000], b"\x00" * 60000)), "wrong_type", id="shape-short"
    ),
    pytest.param(
        datagram(LimArray, ndarray("<f8", [0] * 60000, b"")), "wrong_type", id="shape-60000-dims"
    ),
    # Deep values in error messages and paths.
    pytest.param(
        datagram(
            LimBareDict,
            b"\x81" + msgpack.packb("k" * 30000) + b"\x81\xa0" * 450 + b"\xd4\x05\x00",
        ),
        "wrong_type",
        id="deep-bare-dict-under-a-30KB-key",
    ),
    pytest.param(
        head(LimInts, tid=b"\x91" * DEEP + b"\x00") + b"\x90",
        "unknown_type",
        id="type-id-1000-deep",
    ),
    pytest.param(
        head(LimInts, ids=b"\x91" * DEEP + b"\x00") + b"\x90",
        "bad_header",
        id="msg-id-1000-deep",
    ),
    pytest.param(
        head(LimInts, fp=msgpack.packb("f" * 60000)) + b"\x90",
        "bad_header",
        id="fingerprint-60KB-string",
    ),
]


@pytest.mark.parametrize(("data", "reason"), REFUSED)
def test_hostile_datagram_is_refused_within_the_memory_bound(data: bytes, reason: str) -> None:
    assert len(data) <= MAX
    peak, outcome = peak_of_decode(CODEC, data)
    bound = bound_for(data)
    print(f"\n  {len(data):6} bytes  peak {peak:11,}  bound {bound:11,}  {outcome}"[:160])
    assert isinstance(outcome, DecodeError)
    assert outcome.reason == reason
    assert len(str(outcome)) < 1000  # error messages quote hostile values briefly
    assert peak <= bound


ACCEPTED = [
    pytest.param(filled(LimBareList, b"\x80"), id="empty-maps-in-bare-list"),
    pytest.param(filled_chains(LimBareList, b"\x81\x00", b"\x00", SHALLOW), id="map-chains"),
    pytest.param(filled_chains(LimBareList, b"\x91", b"\x00", SHALLOW), id="array-chains"),
    pytest.param(filled_chains(LimBareList, b"\x81\x00", b"\x00", 50), id="many-map-chains"),
    pytest.param(filled_chains(LimBareList, b"\x91", b"\x00", 50), id="many-array-chains"),
    pytest.param(filled(LimBareList, b"\x91\x80"), id="maps-in-arrays"),
    pytest.param(filled(LimInts, b"\xd0\x80"), id="ints"),
    pytest.param(
        filled(LimPath, b"\x93" + msgpack.packb(spec_of(LimPoint).type_id) + b"\x00\x00"),
        id="nested-messages",
    ),
    pytest.param(
        datagram(
            LimBareDict,
            map_header(16000) + b"".join(msgpack.packb(i) + b"\x80" for i in range(1000, 17000)),
        ),
        id="map-of-16000-empty-maps",
    ),
    pytest.param(
        datagram(LimBareDict, b"\x81" + msgpack.packb("k" * 30000) + b"\x81\xa0" * 450 + b"\x00"),
        id="deep-bare-dict-under-a-30KB-key",
    ),
    pytest.param(datagram(LimBlob, msgpack.packb(b"x" * 65000)), id="bytes"),
    pytest.param(datagram(LimArray, ndarray("<f8", [8000], b"\x01" * 64000)), id="ndarray"),
]


@pytest.mark.parametrize("data", ACCEPTED)
def test_largest_valid_datagrams_stay_within_the_memory_bound(data: bytes) -> None:
    assert len(data) <= MAX
    peak, outcome = peak_of_decode(CODEC, data)
    bound = bound_for(data)
    print(
        f"\n  {len(data):6} bytes  peak {peak:11,}  bound {bound:11,}  "
        f"{peak / len(data):5.1f} B/B  {type(outcome).__name__}"
    )
    assert isinstance(outcome, Message)
    assert peak <= bound


# Pieces of msgpack that cost the most per byte, or lie about what follows.
TOKENS = [
    b"\x80",  # {}
    b"\x81\x00",  # {0: ...
    b"\x81\xa0",  # {"": ...
    b"\x91",  # [...
    b"\x92\x00",  # [0, ...
    b"\x9f",  # 15 items follow
    array_header(256),
    array_header(257),
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
CLASSES = [LimInts, LimText, LimBlob, LimBareList, LimBareDict, LimTable, LimArray, LimPath]


@st.composite
def hostile_datagrams(draw: st.DrawFn) -> bytes:
    """A datagram header, then a random mix of tokens repeated up to ``max_size``."""
    cls = draw(st.sampled_from(CLASSES))
    body = b"".join(draw(st.lists(st.sampled_from(TOKENS), min_size=1, max_size=30)))
    room = MAX - len(head(cls))
    repeat = draw(st.integers(1, max(1, room // len(body))))
    return datagram(cls, body * repeat)[:MAX]


@st.composite
def random_datagrams(draw: st.DrawFn) -> bytes:
    """Random bytes of up to ``max_size``, alone or after a valid header."""
    rng = draw(st.randoms(use_true_random=False))
    size = draw(st.sampled_from([0, 1, 16, 100, 2000, MAX // 2, MAX]))
    tail = rng.randbytes(rng.randrange(size + 1))
    if draw(st.booleans()):
        return tail
    return (head(draw(st.sampled_from(CLASSES))) + tail)[:MAX]


def check_bounded(data: bytes) -> None:
    peak, outcome = peak_of_decode(CODEC, data)
    assert isinstance(outcome, Message | DecodeError)  # anything else has raised already
    if isinstance(outcome, DecodeError):
        assert outcome.reason in DecodeError.REASONS
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


def test_long_arrays_of_valid_messages_decode_as_sent() -> None:
    # Arrays over 256 items take the pure-Python unpacker: same values, same types.
    ints = LimInts(list(range(-20000, 20000, 3)))
    table = LimTable({str(i): list(range(i)) for i in range(300)})
    bare = LimBareList([[i, {"k": [i, i]}] for i in range(1000)])
    for msg in (ints, table, bare):
        assert CODEC.decode(CODEC.encode(msg)) == msg
    assert type(CODEC.decode(CODEC.encode(bare)).v[999][1]["k"]) is list  # type: ignore[attr-defined]


def test_the_bound_is_the_documented_formula() -> None:
    for size in (MIN_DATAGRAM, 1500, MAX):
        expected = (8 + 1 + 256) * size + 256 * 1024
        assert Codec(SPECS, FP, size).max_decode_bytes == expected
    assert CODEC.max_decode_bytes < 18 * 2**20  # the default: about 17 MiB


@pytest.mark.parametrize(("depth", "decodes"), [(MAX_NESTING, True), (MAX_NESTING + 1, False)])
def test_a_field_nests_at_most_what_the_encoder_can_send_again(depth: int, decodes: bool) -> None:
    data = datagram(LimBareDict, b"\x81\xa0" * depth + b"\x00")
    assert len(data) > MAX_NESTING  # smaller datagrams cannot nest that deep: not looked at
    if decodes:
        msg = CODEC.decode(data)
        assert CODEC.decode(CODEC.encode(msg)) == msg
    else:
        with pytest.raises(DecodeError, match="nest too deeply") as caught:
            CODEC.decode(data)
        assert caught.value.reason == "wrong_type"
