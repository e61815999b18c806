"""The codec's msgspec fast path changes costs, never outcomes.

Every datagram is decoded twice, by ``Codec.decode`` (fast path first) and by
``Codec._decode_precisely`` (msgpack and the generated checks, the reference): both
must give the same message, or the same error with the same reason.
"""

from __future__ import annotations

import datetime
from enum import IntEnum
from typing import Any

import msgpack
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cas_async import DecodeError, Message, message, spec_of
from cas_async._codegen import compiled
from cas_async._message import specs_for
from cas_async.transport import Codec
from cas_async.transport import stack_fingerprint as fingerprint_of

from .test_codec_properties import PropAll, PropInner, PropSmall, ids64, ints64, same, wire_values


class FastMode(IntEnum):
    OFF = 0
    ON = 7


@message
class FastAll(Message):
    """A field of every kind the fast path takes."""

    i: int
    f: float
    b: bool
    s: str
    raw: bytes
    nothing: None
    maybe: int | None
    maybe_f: float | None
    ints: list[int]
    floats: list[float]
    texts: tuple[str, ...]
    mode: FastMode
    modes: list[FastMode]
    maybe_ints: list[int] | None
    maybe_mode: FastMode | None


@message
class FastEmpty(Message):
    pass


@message
class FastWide(Message):
    """More than 15 items: the datagram's array header is three bytes."""

    a: int
    b: int
    c: int
    d: int
    e: int
    f: int
    g: int
    h: int


CLASSES = [FastAll, FastEmpty, FastWide, PropSmall, PropInner, PropAll]
SPECS = specs_for(CLASSES)
CODEC = Codec(SPECS, fingerprint_of(3, SPECS))

floats = st.floats(allow_nan=False)
modes = st.sampled_from(FastMode)
headers: dict[str, Any] = {"msg_id": ids64, "robot_id": ints64, "corr_id": ids64}
fast_all = st.builds(
    FastAll,
    i=ints64,
    f=floats,
    b=st.booleans(),
    s=st.text(max_size=8),
    raw=st.binary(max_size=8),
    nothing=st.none(),
    maybe=st.none() | ints64,
    maybe_f=st.none() | floats,
    ints=st.lists(ints64, max_size=4),
    floats=st.lists(floats, max_size=4),
    texts=st.tuples(st.text(max_size=3)),
    mode=modes,
    modes=st.lists(modes, max_size=3),
    maybe_ints=st.none() | st.lists(ints64, max_size=3),
    maybe_mode=st.none() | modes,
    **headers,
)
fast_messages = st.one_of(
    fast_all,
    st.builds(FastWide, *[ints64] * 8, **headers),
    st.builds(FastEmpty, **headers),
    st.builds(PropSmall, n=ints64, note=st.text(max_size=8), **headers),
)


def outcome(decode: Any, data: bytes) -> tuple[str, Any]:
    try:
        return "message", decode(data)
    except DecodeError as exc:
        return "error", (type(exc), exc.reason, str(exc))


def assert_same_outcome(data: bytes) -> None:
    fast, precise = outcome(CODEC.decode, data), outcome(CODEC._decode_precisely, data)
    assert fast[0] == precise[0], (fast, precise)
    if fast[0] == "message":
        assert same(fast[1], precise[1]), (fast, precise)
    else:
        assert fast[1] == precise[1]


def test_flat_classes_get_the_fast_pair_and_others_do_not() -> None:
    for cls in (FastAll, FastEmpty, FastWide, PropSmall, PropInner):
        assert compiled(spec_of(cls)).build is not None, cls
    assert compiled(spec_of(PropAll)).build is None  # nested messages, arrays, maps...


@pytest.mark.slow
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(msg=fast_messages)
def test_fast_round_trip_matches_msgpack(msg: Message) -> None:
    data = CODEC.encode(msg)
    assert msgpack.unpackb(data) == msgpack.unpackb(CODEC._encode_precisely(msg))
    assert same(CODEC.decode(data), msg)
    assert_same_outcome(data)


@st.composite
def field_swaps(draw: st.DrawFn) -> bytes:
    """A valid datagram with one item (header included) replaced by any wire value."""
    row = list(msgpack.unpackb(CODEC.encode(draw(fast_messages)), strict_map_key=False))
    where = draw(st.integers(0, len(row) - 1))
    row[where] = draw(wire_values)
    return msgpack.packb(row)  # type: ignore[no-any-return]


@st.composite
def byte_flips(draw: st.DrawFn) -> bytes:
    data = bytearray(CODEC.encode(draw(fast_messages)))
    for _ in range(draw(st.integers(1, 3))):
        data[draw(st.integers(0, len(data) - 1))] = draw(st.integers(0, 255))
    return bytes(data)


@st.composite
def cuts(draw: st.DrawFn) -> bytes:
    data = CODEC.encode(draw(fast_messages))
    return data[: draw(st.integers(0, len(data) - 1))]


@pytest.mark.slow
@settings(max_examples=600, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.one_of(field_swaps(), byte_flips(), cuts()))
def test_fast_and_precise_decoding_agree_on_any_change(data: bytes) -> None:
    assert_same_outcome(data)


@pytest.mark.parametrize(
    ("msg", "field"),
    [
        pytest.param(PropSmall({1}, "x"), "n", id="set-for-int"),  # type: ignore[arg-type]
        pytest.param(PropSmall(datetime.date(2020, 1, 1)), "n", id="date-for-int"),  # type: ignore[arg-type]
        pytest.param(PropSmall(1, "\ud800"), "note", id="lone-surrogate"),
        pytest.param(PropSmall(2**64), "n", id="int-too-big"),
    ],
)
def test_values_the_fast_encoder_declines_get_msgpack_s_error(msg: Message, field: str) -> None:
    with pytest.raises(Exception, match=field):
        CODEC.encode(msg)


def test_fast_encoder_leaves_int_for_float_to_msgpack_and_decodes_alike() -> None:
    msg = PropInner("w", 3)  # type: ignore[arg-type]
    decoded = CODEC.decode(CODEC.encode(msg))
    assert decoded.weight == 3.0
    assert type(decoded.weight) is float  # type: ignore[attr-defined]


def test_a_wrong_element_is_refused_by_the_receiver_with_its_path() -> None:
    # Elements of lists are not checked when encoding (see codegen._wire_check): a
    # datetime that msgspec can carry reaches the receiver, which refuses it.
    msg = FastAll(1, 1.0, True, "s", b"", None, None, None, [1, datetime.datetime(2020, 1, 1)],
                  [], (), FastMode.ON, [], None, None)  # fmt: skip
    data = CODEC.encode(msg)
    with pytest.raises(DecodeError, match=r"FastAll\.ints\[1\]") as caught:
        CODEC.decode(data)
    assert caught.value.reason == "wrong_type"
