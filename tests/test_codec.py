"""The msgpack codec: round trips, encode errors, strict decoding, stack fingerprints."""

from __future__ import annotations

import datetime
import math
from enum import IntEnum
from typing import Any

import msgpack
import numpy as np
import numpy.typing as npt
import pytest

from cas_async import (
    DecodeError,
    EncodeError,
    Message,
    MessageDefinitionError,
    MsgType,
    StackMismatchError,
    message,
    spec_of,
)
from cas_async._message import specs_for
from cas_async.transport import Codec, describe_fingerprint, stack_fingerprint


class CodecColor(IntEnum):
    RED = 1
    GREEN = 2
    BLUE = 7


@message
class CodecInt(Message):
    v: int


@message
class CodecFloat(Message):
    v: float


@message
class CodecBool(Message):
    v: bool


@message
class CodecStr(Message):
    v: str


@message
class CodecBytes(Message):
    v: bytes


@message
class CodecNone(Message):
    v: None


@message
class CodecOptInt(Message):
    v: int | None


@message
class CodecStrOrInt(Message):
    v: str | int


@message
class CodecListInt(Message):
    v: list[int]


@message
class CodecListFloat(Message):
    v: list[float]


@message
class CodecTupleVar(Message):
    v: tuple[int, ...]


@message
class CodecPair(Message):
    v: tuple[int, str]


@message
class CodecDict(Message):
    v: dict[str, int]


@message
class CodecDictOfLists(Message):
    v: dict[int, list[str]]


@message
class CodecTupleKeys(Message):
    v: dict[tuple[int, int], str]


@message
class CodecBareList(Message):
    v: list  # type: ignore[type-arg]


@message
class CodecBareTuple(Message):
    v: tuple  # type: ignore[type-arg]


@message
class CodecBareDict(Message):
    v: dict  # type: ignore[type-arg]


@message
class CodecEnum(Message):
    v: CodecColor


@message
class CodecEnumList(Message):
    v: list[CodecColor]


@message
class CodecPoint(Message):
    x: float
    y: float


@message
class CodecLine(Message):
    start: CodecPoint
    end: CodecPoint


@message
class CodecPath(Message):
    points: list[CodecPoint]


@message
class CodecMaybePoint(Message):
    v: CodecPoint | None


@message
class CodecArray(Message):
    v: np.ndarray  # type: ignore[type-arg]


@message
class CodecTypedArray(Message):
    v: npt.NDArray[np.float64]


@message
class CodecMixed(Message):
    """Several fields, with and without fast checks, to exercise the generated decoder."""

    a: int
    b: float
    c: list[int]
    d: str
    e: CodecColor
    f: bytes | None = None


@message
class CodecChecked(Message):
    v: int

    def __post_init__(self) -> None:
        if self.v < 0:
            raise ValueError("v must not be negative")


@message(name="Codec'quoted{name}")
class CodecQuoted(Message):
    v: int

    def __post_init__(self) -> None:
        if self.v < 0:
            raise ValueError("negative")


@message
class CodecNode(Message):
    x: int = 0


@message
class CodecTree(CodecNode):
    child: CodecNode | None = None


@message
class CodecListKeys(Message):
    v: dict[list[int], int]


@message
class CodecOutsider(Message):
    """Registered, but not among the messages CODEC accepts."""

    v: int


ACCEPTED: tuple[type[Message], ...] = (
    CodecInt,
    CodecFloat,
    CodecBool,
    CodecStr,
    CodecBytes,
    CodecNone,
    CodecOptInt,
    CodecStrOrInt,
    CodecListInt,
    CodecListFloat,
    CodecTupleVar,
    CodecPair,
    CodecDict,
    CodecDictOfLists,
    CodecTupleKeys,
    CodecBareList,
    CodecBareTuple,
    CodecBareDict,
    CodecEnum,
    CodecEnumList,
    CodecPoint,
    CodecLine,
    CodecPath,
    CodecMaybePoint,
    CodecArray,
    CodecTypedArray,
    CodecMixed,
    CodecChecked,
    CodecQuoted,
    CodecNode,
    CodecTree,
    CodecListKeys,
)
SPECS = specs_for(ACCEPTED)
LAYERS = 3
CODEC = Codec(SPECS, stack_fingerprint(LAYERS, SPECS))
FP = CODEC.fingerprint
HEADER = (0, int(MsgType.ACCEPT), 0, 0, 0, 0)  # msg_id, msg_type, robot_id, src, dst, corr


def tid(cls: type[Message]) -> int:
    return spec_of(cls).type_id


def wire(
    cls: type[Message],
    *fields: Any,
    header: tuple[Any, ...] = HEADER,
    fp: Any = None,
    type_id: Any = None,
) -> bytes:
    """A datagram built by hand: ``[fingerprint, type_id, *header, *fields]``."""
    head = [FP if fp is None else fp, tid(cls) if type_id is None else type_id, *header]
    data: bytes = msgpack.packb([*head, *fields])
    return data


def wire_raw(cls: type[Message], raw_field: bytes) -> bytes:
    """A datagram whose one field is given as raw msgpack bytes (which packb cannot make)."""
    items = [msgpack.packb(x) for x in (FP, tid(cls), *HEADER)]
    return bytes([0x90 + len(items) + 1]) + b"".join(items) + raw_field


def nested(cls: type[Message], *fields: Any) -> list[Any]:
    return [tid(cls), *fields]


def array_wire(array: np.ndarray[Any, Any]) -> list[Any]:
    return [array.dtype.str, list(array.shape), array.tobytes()]


def deep_list(depth: int) -> bytes:
    return b"\x91" * depth + b"\x01"  # [[[...[1]...]]]


def deep_tree_wire(depth: int) -> list[Any]:
    node: Any = None
    for _ in range(depth):
        node = nested(CodecTree, 1, node)
    return node  # type: ignore[no-any-return]


def kinds(value: Any) -> Any:
    """The container and element types of a value, recursively (what == does not see)."""
    if isinstance(value, list | tuple):
        return (type(value), [kinds(item) for item in value])
    if isinstance(value, dict):
        return (dict, sorted((repr(k), kinds(k), kinds(v)) for k, v in value.items()))
    if isinstance(value, Message):
        return (type(value), [kinds(getattr(value, n)) for n in spec_of(type(value)).field_names])
    return type(value)


def round_trip(msg: Message, codec: Codec = CODEC) -> Message:
    return codec.decode(codec.encode(msg))


# --- round trips ---------------------------------------------------------------------------

POINT = CodecPoint(1.5, -2.0)

SAME_VALUE_ROUND_TRIPS = [
    pytest.param(CodecInt(0), id="int-zero"),
    pytest.param(CodecInt(-1), id="int-negative"),
    pytest.param(CodecInt(2**63 - 1), id="int-max-int64"),
    pytest.param(CodecInt(-(2**63)), id="int-min-int64"),
    pytest.param(CodecInt(2**64 - 1), id="int-max-uint64"),
    pytest.param(CodecFloat(1.25), id="float"),
    pytest.param(CodecFloat(-0.0), id="float-negative-zero"),
    pytest.param(CodecFloat(math.inf), id="float-inf"),
    pytest.param(CodecFloat(5e-324), id="float-subnormal"),
    pytest.param(CodecBool(True), id="bool-true"),
    pytest.param(CodecBool(False), id="bool-false"),
    pytest.param(CodecStr(""), id="str-empty"),
    pytest.param(CodecStr("héllo ✓ \x00"), id="str-unicode"),
    pytest.param(CodecBytes(b""), id="bytes-empty"),
    pytest.param(CodecBytes(bytes(range(256))), id="bytes-all-values"),
    pytest.param(CodecNone(None), id="none"),
    pytest.param(CodecOptInt(None), id="optional-none"),
    pytest.param(CodecOptInt(5), id="optional-int"),
    pytest.param(CodecStrOrInt("a"), id="union-str"),
    pytest.param(CodecStrOrInt(1), id="union-int"),
    pytest.param(CodecListInt([]), id="list-empty"),
    pytest.param(CodecListInt([1, -2, 2**64 - 1]), id="list-int"),
    pytest.param(CodecListFloat([1.0, -0.5]), id="list-float"),
    pytest.param(CodecTupleVar(()), id="tuple-var-empty"),
    pytest.param(CodecTupleVar((1, 2, 3)), id="tuple-var"),
    pytest.param(CodecPair((1, "a")), id="tuple-fixed"),
    pytest.param(CodecDict({}), id="dict-empty"),
    pytest.param(CodecDict({"a": 1, "b": -2}), id="dict"),
    pytest.param(CodecDictOfLists({1: ["x"], -2: []}), id="dict-of-lists"),
    pytest.param(CodecTupleKeys({(1, 2): "a", (3, 4): "b"}), id="dict-tuple-keys"),
    pytest.param(CodecBareList([1, "a", None, 2.5, b"x", [2, [3]], {"k": [True]}]), id="bare-list"),
    pytest.param(CodecBareTuple((1, "a", None)), id="bare-tuple"),
    pytest.param(CodecBareDict({"a": [1, 2], 3: {"b": b"x"}, None: 1.5}), id="bare-dict"),
    pytest.param(CodecEnum(CodecColor.BLUE), id="int-enum"),
    pytest.param(CodecEnumList([CodecColor.RED, CodecColor.GREEN]), id="list-int-enum"),
    pytest.param(POINT, id="message-of-floats"),
    pytest.param(CodecLine(POINT, CodecPoint(0.0, 0.0)), id="nested-message"),
    pytest.param(CodecPath([POINT, POINT]), id="list-of-nested"),
    pytest.param(CodecMaybePoint(POINT), id="optional-nested-set"),
    pytest.param(CodecMaybePoint(None), id="optional-nested-none"),
    pytest.param(CodecTree(1, CodecTree(2, CodecNode(3))), id="nested-subclass"),
    pytest.param(CodecMixed(1, 2.5, [3], "four", CodecColor.GREEN, b"six"), id="mixed-fast-path"),
    pytest.param(CodecChecked(3), id="post-init-accepts"),
]


@pytest.mark.parametrize("msg", SAME_VALUE_ROUND_TRIPS)
def test_round_trip_keeps_values_and_types(msg: Message) -> None:
    decoded = round_trip(msg)
    assert type(decoded) is type(msg)
    assert decoded == msg
    assert kinds(decoded) == kinds(msg)


@pytest.mark.parametrize(
    ("msg", "expected"),
    [
        pytest.param(CodecFloat(3), CodecFloat(3.0), id="int-in-float-field"),
        pytest.param(CodecListFloat([1, 2.5]), CodecListFloat([1.0, 2.5]), id="ints-in-floats"),
        pytest.param(CodecTupleVar([1, 2]), CodecTupleVar((1, 2)), id="list-for-tuple"),  # type: ignore[arg-type]
        pytest.param(CodecListInt((1, 2)), CodecListInt([1, 2]), id="tuple-for-list"),  # type: ignore[arg-type]
        pytest.param(CodecEnum(2), CodecEnum(CodecColor.GREEN), id="int-for-enum"),  # type: ignore[arg-type]
        pytest.param(CodecInt(np.int64(5)), CodecInt(5), id="numpy-int-scalar"),  # type: ignore[arg-type]
        pytest.param(CodecFloat(np.float32(0.5)), CodecFloat(0.5), id="numpy-float-scalar"),  # type: ignore[arg-type]
        pytest.param(CodecBool(np.bool_(True)), CodecBool(True), id="numpy-bool-scalar"),  # type: ignore[arg-type]
        pytest.param(
            CodecMixed(1, 2, [3], "four", CodecColor.GREEN),  # type: ignore[arg-type]
            CodecMixed(1, 2.0, [3], "four", CodecColor.GREEN),
            id="mixed-slow-path",
        ),
        pytest.param(
            CodecBareTuple((1, (2, 3))), CodecBareTuple((1, [2, 3])), id="bare-tuple-inner-list"
        ),
        pytest.param(
            CodecLine(CodecPoint(1.0, 2.0, msg_id=5), POINT),
            CodecLine(CodecPoint(1.0, 2.0), POINT),
            id="nested-header-not-sent",
        ),
    ],
)
def test_round_trip_normalises_to_the_declared_type(msg: Message, expected: Message) -> None:
    decoded = round_trip(msg)
    assert decoded == expected
    assert kinds(decoded) == kinds(expected)


def test_nan_round_trips() -> None:
    decoded = round_trip(CodecFloat(math.nan))
    assert isinstance(decoded, CodecFloat)
    assert math.isnan(decoded.v)


@pytest.mark.parametrize(
    "header",
    [
        pytest.param({}, id="defaults"),
        pytest.param(
            {"msg_id": 7, "msg_type": MsgType.NEGOTIATION, "robot_id": 3, "src_layer": 1},
            id="negotiation",
        ),
        pytest.param({"msg_type": MsgType.DENY, "corr_id": 7, "dst_layer": 4}, id="deny-reply"),
        pytest.param({"msg_id": 2**64 - 1, "robot_id": -(2**63)}, id="extremes"),
    ],
)
def test_header_round_trips(header: dict[str, Any]) -> None:
    msg = CodecInt(1, **header)
    decoded = round_trip(msg)
    assert decoded == msg
    assert type(decoded.msg_type) is MsgType


@pytest.mark.parametrize(
    "buffer", [bytes, bytearray, memoryview], ids=["bytes", "bytearray", "memoryview"]
)
def test_decode_accepts_any_bytes_like(buffer: Any) -> None:
    assert CODEC.decode(buffer(CODEC.encode(CodecInt(4)))) == CodecInt(4)


ARRAYS = [
    pytest.param(np.array([1.5, -2.0]), id="float64"),
    pytest.param(np.arange(6, dtype=np.float32).reshape(2, 3), id="float32-2d"),
    pytest.param(np.array([1.0, 2.0], dtype=np.float16), id="float16"),
    pytest.param(np.array([True, False]), id="bool"),
    pytest.param(np.array([-128, 127], dtype=np.int8), id="int8"),
    pytest.param(np.array([0, 255], dtype=np.uint8), id="uint8"),
    pytest.param(np.array([-1], dtype=np.int16), id="int16"),
    pytest.param(np.arange(24, dtype=np.int32).reshape(2, 3, 4), id="int32-3d"),
    pytest.param(np.array([2**63 - 1], dtype=np.int64), id="int64"),
    pytest.param(np.array([2**64 - 1], dtype=np.uint64), id="uint64"),
    pytest.param(np.array([1 + 2j], dtype=np.complex64), id="complex64"),
    pytest.param(np.array([[1 - 1j]], dtype=np.complex128), id="complex128"),
    pytest.param(np.array([1, 2], dtype=">i4"), id="big-endian"),
    pytest.param(np.array(3.5), id="zero-dim"),
    pytest.param(np.zeros((0,)), id="empty"),
    pytest.param(np.zeros((2, 0, 4), dtype=np.int16), id="empty-3d"),
    pytest.param(np.asfortranarray(np.arange(6.0).reshape(2, 3)), id="fortran-order"),
    pytest.param(np.arange(10)[::3], id="strided-view"),
    pytest.param(np.array([math.nan, math.inf]), id="nan-inf"),
]


@pytest.mark.parametrize("array", ARRAYS)
def test_ndarray_round_trip_keeps_dtype_shape_and_values(array: np.ndarray[Any, Any]) -> None:
    decoded = round_trip(CodecArray(array))
    assert isinstance(decoded, CodecArray)
    result = decoded.v
    assert type(result) is np.ndarray
    assert result.dtype == array.dtype
    assert result.shape == array.shape
    assert result.tobytes() == array.tobytes()  # bitwise: NaN compares equal too
    assert result.flags.writeable
    assert result.flags.c_contiguous
    result[...] = 0  # a normal array, not a read-only view on the datagram


def test_ndarray_typed_annotation_round_trips() -> None:
    decoded = round_trip(CodecTypedArray(np.array([[1.0, 2.0]])))
    assert isinstance(decoded, CodecTypedArray)
    np.testing.assert_array_equal(decoded.v, [[1.0, 2.0]])


def test_decoded_arrays_do_not_share_memory() -> None:
    data = CODEC.encode(CodecArray(np.arange(4.0)))
    first, second = CODEC.decode(data), CODEC.decode(data)
    assert isinstance(first, CodecArray)
    assert isinstance(second, CodecArray)
    first.v[0] = 99.0
    assert second.v[0] == 0.0


def test_int_enum_decodes_to_the_member() -> None:
    decoded = CODEC.decode(wire(CodecEnum, 7))
    assert isinstance(decoded, CodecEnum)
    assert decoded.v is CodecColor.BLUE


def test_nested_messages_decode_to_their_classes_with_a_default_header() -> None:
    decoded = CODEC.decode(wire(CodecTree, 1, nested(CodecTree, 2, nested(CodecNode, 3))))
    assert decoded == CodecTree(1, CodecTree(2, CodecNode(3)))
    assert isinstance(decoded, CodecTree)
    assert type(decoded.child) is CodecTree
    assert decoded.child.msg_type is MsgType.ACCEPT


def test_post_init_runs_on_decode() -> None:
    with pytest.raises(DecodeError, match="CodecChecked: rejected by __post_init__: v must not"):
        CODEC.decode(wire(CodecChecked, -1))


def test_message_name_with_quotes_and_braces_is_safe_in_the_generated_decoder() -> None:
    assert CODEC.decode(wire(CodecQuoted, 1)) == CodecQuoted(1)
    with pytest.raises(DecodeError, match=r"Codec'quoted\{name\}: rejected by __post_init__"):
        CODEC.decode(wire(CodecQuoted, -1))


# --- encode errors -------------------------------------------------------------------------


def test_max_size_below_64_is_refused() -> None:
    with pytest.raises(ValueError, match="at least 64"):
        Codec(SPECS, FP, max_size=63)


def test_encode_above_the_limit_names_the_limit() -> None:
    small = Codec(SPECS, FP, max_size=64)
    assert len(small.encode(CodecBytes(b"x" * 10))) <= 64
    with pytest.raises(
        EncodeError, match=r"CodecBytes encodes to \d+ bytes, above the limit of 64"
    ):
        small.encode(CodecBytes(b"x" * 100))


@pytest.mark.parametrize(
    ("msg", "field"),
    [
        pytest.param(CodecBareList([object()]), "v", id="object"),
        pytest.param(CodecBareList([{1, 2}]), "v", id="set"),
        pytest.param(CodecBareList([1j]), "v", id="complex"),
        pytest.param(CodecBareList([datetime.date(2020, 1, 1)]), "v", id="date"),
        pytest.param(CodecBareDict({frozenset(): 1}), "v", id="frozenset-key"),
        pytest.param(CodecInt(2**64), "v", id="int-too-big"),
        pytest.param(CodecInt(-(2**63) - 1), "v", id="int-too-small"),
        pytest.param(CodecStr("\ud800"), "v", id="lone-surrogate"),
        pytest.param(CodecArray(np.array(["text"])), "v", id="ndarray-of-str"),
        pytest.param(CodecArray(np.array([object()])), "v", id="ndarray-of-objects"),
        pytest.param(CodecArray(np.array(["2020"], dtype="M8[D]")), "v", id="ndarray-datetime"),
        pytest.param(CodecMixed(1, 2.0, [3], "x", CodecColor.RED, f={1}), "f", id="last-field"),  # type: ignore[arg-type]
        pytest.param(CodecLine(POINT, CodecPoint(object(), 1.0)), "end", id="inside-nested"),  # type: ignore[arg-type]
    ],
)
def test_unencodable_value_names_the_field(msg: Message, field: str) -> None:
    with pytest.raises(EncodeError, match=rf"cannot encode {type(msg).__name__}: field '{field}'"):
        CODEC.encode(msg)
    # A failed encode leaves nothing behind in the reused packer.
    assert CODEC.decode(CODEC.encode(CodecInt(7))) == CodecInt(7)


def test_unencodable_header_is_an_encode_error() -> None:
    with pytest.raises(EncodeError, match="cannot encode CodecInt"):
        CODEC.encode(CodecInt(1, msg_id=2**64))


def test_self_referencing_value_is_an_encode_error() -> None:
    loop: list[Any] = []
    loop.append(loop)
    with pytest.raises(EncodeError, match="field 'v'"):
        CODEC.encode(CodecBareList(loop))


def test_encode_refuses_a_message_type_this_codec_does_not_accept() -> None:
    with pytest.raises(EncodeError, match="CodecOutsider is not among the messages"):
        CODEC.encode(CodecOutsider(1))


def test_encode_of_an_undecorated_class_says_to_decorate_it() -> None:
    class CodecUndecorated(Message):
        pass

    # Already when it is made, before any codec sees it.
    with pytest.raises(MessageDefinitionError, match="decorate the class with @message"):
        CODEC.encode(CodecUndecorated())


# --- decode errors -------------------------------------------------------------------------

VALID = wire(CodecInt, 1)
POINT_WIRE = nested(CodecPoint, 1.0, 2.0)
F8 = np.arange(2.0)  # two float64s: 16 bytes

DECODE_ERRORS = [
    # Not msgpack at all.
    pytest.param(b"", "malformed", "not a msgpack datagram", id="empty"),
    pytest.param(b"\xc1", "malformed", "not a msgpack datagram", id="never-used-byte"),
    pytest.param(b"\xff" * 40, "malformed", "not a msgpack datagram", id="garbage"),
    pytest.param(VALID[:-1], "malformed", "not a msgpack datagram", id="truncated"),
    pytest.param(VALID[:1], "malformed", "not a msgpack datagram", id="truncated-to-one-byte"),
    pytest.param(VALID + b"\x00", "malformed", "not a msgpack datagram", id="trailing-bytes"),
    pytest.param(
        wire_raw(CodecStr, b"\xa2\xff\xfe"), "malformed", "UnicodeDecodeError", id="bad-utf8"
    ),
    pytest.param(
        wire_raw(CodecBareList, b"\xd4\xff\x00"), "malformed", "timestamp", id="bad-timestamp"
    ),
    pytest.param(
        wire_raw(CodecBareList, deep_list(5000)), "malformed", "too deeply", id="too-deep"
    ),
    pytest.param(
        wire_raw(CodecBareDict, b"\x81\x80\x01"), "malformed", "unhashable", id="map-as-map-key"
    ),
    # Not a datagram.
    pytest.param(msgpack.packb(5), "bad_header", "expected an array", id="not-an-array-int"),
    pytest.param(msgpack.packb("x"), "bad_header", "expected an array", id="not-an-array-str"),
    pytest.param(msgpack.packb({0: 1}), "bad_header", "expected an array", id="not-an-array-map"),
    pytest.param(msgpack.packb(None), "bad_header", "expected an array", id="not-an-array-nil"),
    pytest.param(msgpack.packb([]), "bad_header", "expected an array", id="empty-array"),
    pytest.param(
        msgpack.packb([FP, tid(CodecInt), 0, 1, 0]), "bad_header", "header", id="short-header"
    ),
    # Header with wrong types.
    pytest.param(
        wire(CodecInt, 1, header=("x", 1, 0, 0, 0, 0)), "bad_header", "six ints", id="msg-id-str"
    ),
    pytest.param(
        wire(CodecInt, 1, header=(0, 1.0, 0, 0, 0, 0)), "bad_header", "six ints", id="type-float"
    ),
    pytest.param(
        wire(CodecInt, 1, header=(0, 1, True, 0, 0, 0)), "bad_header", "six ints", id="robot-bool"
    ),
    pytest.param(
        wire(CodecInt, 1, header=(0, 1, 0, [], 0, 0)), "bad_header", "six ints", id="src-array"
    ),
    pytest.param(
        wire(CodecInt, 1, header=(0, 1, 0, 0, 0, None)), "bad_header", "six ints", id="corr-nil"
    ),
    pytest.param(
        wire(CodecInt, 1, header=(0, 3, 0, 0, 0, 0)), "bad_header", "six ints", id="msg-type-3"
    ),
    pytest.param(
        wire(CodecInt, 1, header=(0, -1, 0, 0, 0, 0)), "bad_header", "six ints", id="msg-type-neg"
    ),
    pytest.param(wire(CodecInt, 1, fp="x"), "bad_header", "fingerprint", id="fingerprint-str"),
    pytest.param(
        wire(CodecInt, 1, fp=float(FP)), "bad_header", "fingerprint", id="fingerprint-float"
    ),
    pytest.param(wire(CodecInt, 1, fp=[FP]), "bad_header", "fingerprint", id="fp-array"),
    pytest.param(wire(CodecInt, 1, fp=True), "bad_header", "fingerprint", id="fp-bool"),
    pytest.param(
        wire(CodecInt, 1, fp=FP + 1, header=(0, 1, "r", 0, 0, 0)),
        "bad_header",
        "fingerprint",
        id="other-fingerprint-bad-robot-id",
    ),
    # Unknown type.
    pytest.param(wire(CodecInt, 1, type_id=7), "unknown_type", "type id 7", id="unknown-id"),
    pytest.param(
        wire(CodecInt, 1, type_id="CodecInt"), "unknown_type", "'CodecInt'", id="type-id-str"
    ),
    pytest.param(
        wire(CodecInt, 1, type_id=float(tid(CodecInt))),
        "unknown_type",
        "unknown message type id",
        id="type-id-float",
    ),
    pytest.param(
        wire(CodecOutsider, 1),
        "unknown_type",
        f"unknown message type id {tid(CodecOutsider)}",
        id="registered-not-accepted",
    ),
    # Wrong arity.
    pytest.param(wire(CodecInt), "wrong_arity", "CodecInt: expected 1 fields, got 0", id="none"),
    pytest.param(wire(CodecInt, 1, 2), "wrong_arity", "expected 1 fields, got 2", id="too-many"),
    pytest.param(wire(CodecLine, POINT_WIRE), "wrong_arity", "expected 2", id="too-few"),
    pytest.param(
        wire(CodecLine, nested(CodecPoint, 1.0), POINT_WIRE),
        "wrong_arity",
        "CodecLine.start: CodecPoint has 2 fields, got 1",
        id="nested-arity",
    ),
]

WRONG_TYPES = [
    pytest.param(CodecInt, "x", "CodecInt.v: expected int, got str", id="int-got-str"),
    pytest.param(CodecInt, True, "CodecInt.v: expected int, got bool", id="int-got-bool"),
    pytest.param(CodecInt, 1.0, "CodecInt.v: expected int, got float", id="int-got-float"),
    pytest.param(CodecInt, [1], "CodecInt.v: expected int, got array", id="int-got-array"),
    pytest.param(CodecFloat, "1", "CodecFloat.v: expected float, got str", id="float-got-str"),
    pytest.param(CodecFloat, False, "CodecFloat.v: expected float, got bool", id="float-got-bool"),
    pytest.param(CodecBool, 1, "CodecBool.v: expected bool, got int", id="bool-got-int"),
    pytest.param(CodecStr, b"x", "CodecStr.v: expected str, got bytes", id="str-got-bytes"),
    pytest.param(CodecBytes, "x", "CodecBytes.v: expected bytes, got str", id="bytes-got-str"),
    pytest.param(CodecNone, 0, "CodecNone.v: expected None, got int", id="none-got-int"),
    pytest.param(
        CodecOptInt, "x", "CodecOptInt.v: expected int | None, got str", id="optional-got-str"
    ),
    pytest.param(CodecStrOrInt, 1.5, "CodecStrOrInt.v: expected str | int, got float", id="union"),
    pytest.param(
        CodecListInt, 5, r"CodecListInt.v: expected list\[int\], got int", id="list-got-int"
    ),
    pytest.param(
        CodecListInt, [1, "x"], r"CodecListInt.v\[1\]: expected int, got str", id="list-element"
    ),
    pytest.param(
        CodecListInt, [1, True], r"CodecListInt.v\[1\]: expected int, got bool", id="list-bool"
    ),
    pytest.param(
        CodecListFloat, [1.0, None], r"CodecListFloat.v\[1\]: expected float", id="list-float"
    ),
    pytest.param(
        CodecTupleVar,
        {"a": 1},
        r"CodecTupleVar.v: expected tuple\[int, ...\], got dict",
        id="tuple",
    ),
    pytest.param(
        CodecPair, [1], r"CodecPair.v: expected tuple\[int, str\], got array", id="pair-length"
    ),
    pytest.param(CodecPair, [1, 2], r"CodecPair.v\[1\]: expected str, got int", id="pair-item"),
    pytest.param(CodecDict, [1], r"CodecDict.v: expected dict\[str, int\], got array", id="dict"),
    pytest.param(CodecDict, {1: 1}, "CodecDict.v key: expected str, got int", id="dict-key"),
    pytest.param(
        CodecDict, {"a": "b"}, r"CodecDict.v\['a'\]: expected int, got str", id="dict-value"
    ),
    pytest.param(
        CodecDictOfLists,
        {1: ["a", 2]},
        r"CodecDictOfLists.v\[1\]\[1\]: expected str, got int",
        id="dict-list-item",
    ),
    pytest.param(
        CodecTupleKeys, {(1, "x"): "a"}, r"CodecTupleKeys.v key\[1\]: expected int", id="tuple-key"
    ),
    pytest.param(
        CodecBareList,
        [1, msgpack.ExtType(5, b"x")],
        r"CodecBareList.v\[1\]: expected a plain value, got ExtType",
        id="bare-list-ext",
    ),
    pytest.param(
        CodecBareDict, {(1, 2): 1}, "CodecBareDict.v key: expected a plain key", id="bare-dict-key"
    ),
    pytest.param(CodecBareDict, [1], "CodecBareDict.v: expected dict, got array", id="bare-dict"),
    pytest.param(CodecBareTuple, 1, "CodecBareTuple.v: expected tuple, got int", id="bare-tuple"),
    pytest.param(
        CodecEnum, 3, r"CodecEnum.v: expected CodecColor \(one of \[1, 2, 7\]\), got int", id="enum"
    ),
    pytest.param(CodecEnum, "RED", "CodecEnum.v: expected CodecColor", id="enum-name"),
    pytest.param(CodecEnum, True, "CodecEnum.v: expected CodecColor", id="enum-bool"),
    pytest.param(
        CodecEnumList, [1, 4], r"CodecEnumList.v\[1\]: expected CodecColor", id="enum-list"
    ),
    pytest.param(
        CodecLine, 5, r"CodecLine.start: expected CodecPoint \[type_id", id="nested-not-array"
    ),
    pytest.param(CodecLine, [], "CodecLine.start: expected CodecPoint", id="nested-empty"),
    pytest.param(CodecLine, ["x", 1.0, 2.0], "CodecLine.start: expected", id="nested-id-str"),
    pytest.param(
        CodecLine,
        nested(CodecInt, 1),
        f"CodecLine.start: type id {tid(CodecInt)} is not a CodecPoint",
        id="nested-other-type",
    ),
    pytest.param(
        CodecLine,
        [7, 1.0, 2.0],
        "CodecLine.start: type id 7 is not a CodecPoint",
        id="nested-unknown-id",
    ),
    pytest.param(
        CodecLine,
        nested(CodecPoint, "a", 1.0),
        "CodecLine.start.x: expected float, got str",
        id="nested-field",
    ),
    pytest.param(
        CodecPath,
        [POINT_WIRE, nested(CodecPoint, 1.0, None)],
        r"CodecPath.points\[1\].y: expected float, got NoneType",
        id="nested-in-list",
    ),
    pytest.param(
        CodecMaybePoint, 5, r"CodecMaybePoint.v: expected CodecPoint \| None", id="optional-nested"
    ),
    pytest.param(
        CodecTree,
        nested(CodecPoint, 1.0, 2.0),
        "CodecTree.child: expected CodecNode | None",
        id="nested-not-a-subclass",
    ),
    pytest.param(CodecChecked, -1, "CodecChecked: rejected by __post_init__", id="post-init"),
    pytest.param(CodecListKeys, {(1, 2): 3}, "CodecListKeys.v: unhashable key", id="list-key"),
    # numpy arrays
    pytest.param(CodecArray, 5, r"CodecArray.v: expected ndarray \[dtype", id="array-int"),
    pytest.param(CodecArray, ["<f8", [1]], "CodecArray.v: expected ndarray", id="array-pair"),
    pytest.param(CodecArray, [1, [1], b""], "CodecArray.v: expected ndarray", id="dtype-int"),
    pytest.param(CodecArray, ["<f8", 1, b""], "CodecArray.v: expected ndarray", id="shape-int"),
    pytest.param(CodecArray, ["<f8", [1], "x"], "CodecArray.v: expected ndarray", id="data-str"),
    pytest.param(CodecArray, ["|O", [1], b"\0" * 8], "'|O' is not a numeric", id="object"),
    pytest.param(CodecArray, ["<U1", [1], b"\0" * 4], "'<U1' is not a numeric", id="unicode"),
    pytest.param(CodecArray, ["|S1", [1], b"\0"], "'|S1' is not a numeric", id="bytes"),
    pytest.param(CodecArray, ["a1", [1], b"\0"], "'a1' is not a numeric", id="deprecated-alias"),
    pytest.param(CodecArray, ["<M8[s]", [1], b"\0" * 8], "is not a numeric", id="datetime"),
    pytest.param(CodecArray, ["<m8", [1], b"\0" * 8], "is not a numeric", id="timedelta"),
    pytest.param(CodecArray, ["<i4,<i4", [1], b"\0" * 8], "is not a numeric", id="structured"),
    pytest.param(CodecArray, ["(2,)<i4", [1], b"\0" * 8], "is not a numeric", id="subarray"),
    pytest.param(CodecArray, ["V8", [1], b"\0" * 8], "is not a numeric", id="void"),
    pytest.param(CodecArray, ["float64", [1], b"\0" * 8], "is not a numeric", id="long-name"),
    pytest.param(CodecArray, ["", [0], b""], "is not a numeric", id="empty-dtype"),
    pytest.param(CodecArray, ["<i3", [1], b"\0" * 3], "unknown dtype '<i3'", id="odd-size"),
    pytest.param(CodecArray, ["<f1", [1], b"\0"], "unknown dtype '<f1'", id="f1"),
    pytest.param(
        CodecArray,
        [*array_wire(F8)[:2], b"\0" * 15],
        r"shape \(2,\) of <f8 needs 16 bytes, got 15",
        id="too-few-bytes",
    ),
    pytest.param(
        CodecArray,
        ["<f8", [3], F8.tobytes()],
        r"shape \(3,\) of <f8 needs 24 bytes, got 16",
        id="shape-too-big",
    ),
    pytest.param(CodecArray, ["<f8", [], b"\0" * 16], "needs 8 bytes, got 16", id="zero-dim"),
    pytest.param(CodecArray, ["<f8", [-2], b""], "bad shape", id="negative-dim"),
    pytest.param(CodecArray, ["<f8", [2.0], F8.tobytes()], "bad shape", id="float-dim"),
    pytest.param(CodecArray, ["<f8", [True], b"\0" * 8], "bad shape", id="bool-dim"),
    pytest.param(CodecArray, ["<f8", [1] * 33, b"\0" * 8], "bad shape", id="too-many-dims"),
    pytest.param(CodecArray, ["<f8", [0, 2**62, 2**62], b""], "bad shape", id="huge-empty"),
    pytest.param(CodecArray, ["<f8", [0, 2**64 - 1], b""], "bad shape", id="huge-dim"),
    pytest.param(CodecTypedArray, ["|O", [0], b""], "CodecTypedArray.v: dtype", id="typed-array"),
]


@pytest.mark.parametrize(("data", "reason", "match"), DECODE_ERRORS)
def test_decode_error_reason(data: bytes, reason: str, match: str) -> None:
    with pytest.raises(DecodeError, match=match) as caught:
        CODEC.decode(data)
    assert caught.value.reason == reason
    assert reason in DecodeError.REASONS
    assert type(caught.value) is DecodeError


FIELDS_BEFORE: dict[type[Message], list[Any]] = {CodecTree: [1]}
FIELDS_AFTER: dict[type[Message], list[Any]] = {CodecLine: [POINT_WIRE]}


@pytest.mark.parametrize(("cls", "value", "match"), WRONG_TYPES)
def test_decode_wrong_field_type_names_the_field(
    cls: type[Message], value: Any, match: str
) -> None:
    # The value under test goes in the one field the match names; the others are valid.
    fields = [*FIELDS_BEFORE.get(cls, []), value, *FIELDS_AFTER.get(cls, [])]
    assert len(fields) == len(spec_of(cls).field_names)
    with pytest.raises(DecodeError, match=match) as caught:
        CODEC.decode(wire(cls, *fields))
    assert caught.value.reason == "wrong_type"
    assert type(caught.value) is DecodeError


@pytest.mark.parametrize(
    "data",
    [
        pytest.param(wire_raw(CodecBareList, deep_list(960)), id="bare-list"),
        pytest.param(wire_raw(CodecBareTuple, deep_list(960)), id="bare-tuple"),
        pytest.param(wire_raw(CodecBareDict, b"\x81\x01" + deep_list(960)), id="bare-dict"),
        pytest.param(wire(CodecTree, 1, deep_tree_wire(600)), id="recursive-messages"),
    ],
)
def test_deep_nesting_is_a_decode_error_not_a_recursion_error(data: bytes) -> None:
    # The structure check allows about 990 levels less the caller's stack (Python's
    # recursion limit), the converters about as many: a datagram nested that deep
    # decodes, or is refused by one of them; it never raises a RecursionError.
    try:
        outcome = type(CODEC.decode(data)).__name__
    except DecodeError as caught:
        outcome = caught.reason
    assert outcome in {
        "CodecBareList",
        "CodecBareTuple",
        "CodecBareDict",
        "malformed",
        "wrong_type",
    }


def test_moderately_deep_recursive_messages_decode() -> None:
    decoded = CODEC.decode(wire(CodecTree, 1, deep_tree_wire(50)))
    depth = 0
    node = decoded
    while isinstance(node, CodecTree) and node.child is not None:
        node, depth = node.child, depth + 1
    assert depth == 50


def test_decode_above_max_size_is_oversize() -> None:
    small = Codec(SPECS, FP, max_size=64)
    ok = small.encode(CodecBytes(b""))
    assert small.decode(ok) == CodecBytes(b"")
    with pytest.raises(DecodeError, match="65 bytes, above the limit of 64") as caught:
        small.decode(ok + b"\x00" * (65 - len(ok)))
    assert caught.value.reason == "oversize"
    # Checked before parsing: even a valid datagram is refused when too long.
    with pytest.raises(DecodeError) as caught:
        small.decode(CODEC.encode(CodecBytes(b"x" * 100)))
    assert caught.value.reason == "oversize"


# --- stack fingerprints --------------------------------------------------------------------


def test_stack_mismatch_names_sender_and_both_fingerprints() -> None:
    theirs = Codec(SPECS, stack_fingerprint(LAYERS + 1, SPECS))
    data = theirs.encode(CodecInt(1, robot_id=42))
    with pytest.raises(StackMismatchError) as caught:
        CODEC.decode(data)
    error = caught.value
    assert isinstance(error, DecodeError)
    assert error.reason == "stack_mismatch"
    assert (error.sender, error.theirs, error.ours) == (42, theirs.fingerprint, FP)
    text = str(error)
    assert "robot 42" in text
    assert describe_fingerprint(theirs.fingerprint) in text
    assert describe_fingerprint(FP) in text


def test_stack_mismatch_is_reported_before_the_type_id_is_looked_at() -> None:
    with pytest.raises(StackMismatchError) as caught:
        CODEC.decode(wire(CodecInt, 1, fp=FP ^ 1, type_id=7, header=(0, 1, 5, 0, 0, 0)))
    assert (caught.value.sender, caught.value.theirs) == (5, FP ^ 1)


def test_fingerprint_changes_with_layer_count() -> None:
    prints = {stack_fingerprint(layers, SPECS) for layers in range(1, 10)}
    assert len(prints) == 9
    assert stack_fingerprint(5, SPECS) >> 24 == 5
    assert describe_fingerprint(stack_fingerprint(5, SPECS)).startswith("5 layers, message set 0x")


@pytest.mark.parametrize(
    ("one", "other"),
    [
        pytest.param([CodecInt], [CodecInt, CodecStr], id="one-more-message"),
        pytest.param([CodecInt], [CodecStr], id="another-message"),
        pytest.param([CodecListInt], [CodecListFloat], id="another-field-type"),
        pytest.param([], [CodecInt], id="empty-set"),
        pytest.param(ACCEPTED, ACCEPTED[:-1], id="one-less"),
    ],
)
def test_fingerprint_changes_with_the_message_set(
    one: list[type[Message]], other: list[type[Message]]
) -> None:
    assert stack_fingerprint(LAYERS, specs_for(one)) != stack_fingerprint(LAYERS, specs_for(other))


def test_fingerprint_does_not_depend_on_the_order_of_classes() -> None:
    assert stack_fingerprint(2, specs_for([CodecInt, CodecStr, CodecPoint])) == stack_fingerprint(
        2, specs_for([CodecPoint, CodecStr, CodecInt])
    )
    assert stack_fingerprint(LAYERS, specs_for(ACCEPTED[::-1])) == FP


def test_schema_text_describes_the_wire_layout() -> None:
    assert spec_of(CodecEnum).schema.endswith(":CodecEnum(v:CodecColor[1, 2, 7])")
    assert spec_of(CodecLine).schema.endswith(":CodecLine(start:CodecPoint,end:CodecPoint)")
    assert spec_of(CodecOptInt).schema.endswith(":CodecOptInt(v:int | None)")


def test_robots_of_one_stack_in_one_thread_share_one_codec() -> None:
    import threading

    @message
    class SharedA(Message):
        x: int

    stack = (SharedA,)
    first = Codec.shared(2, stack, 1400)
    assert Codec.shared(2, stack, 1400) is first
    assert Codec.shared(3, stack, 1400) is not first  # another layer count
    assert Codec.shared(2, stack, 9000) is not first  # another datagram limit
    assert Codec.shared(2, stack, 1400).fingerprint == Codec.for_stack(2, stack, 1400).fingerprint
    everything = Codec.shared(2, None)
    assert Codec.shared(2, None) is everything

    @message
    class SharedB(Message):
        y: int

    # Registering a message changes the set of "every registered message".
    assert SharedB in Codec.shared(2, None).message_classes
    assert SharedB not in everything.message_classes
    elsewhere: list[Codec] = []
    thread = threading.Thread(target=lambda: elsewhere.append(Codec.shared(2, stack, 1400)))
    thread.start()
    thread.join(10)
    assert elsewhere
    assert elsewhere[0] is not first
