"""The codec: round trips, encode errors, every decode reason, stack fingerprints."""

from __future__ import annotations

import math
from enum import IntEnum
from typing import Annotated, Any

import msgpack
import msgspec
import numpy as np
import numpy.typing as npt
import pytest

from cas_async import (
    DecodeError,
    EncodeError,
    Message,
    MsgType,
    StackMismatchError,
)
from cas_async._wire._fingerprint import describe_fingerprint
from cas_async.transport import Codec
from tests.wire import datagram, tag_of


class Color(IntEnum):
    RED = 1
    GREEN = 2
    BLUE = 7


class Vec(msgspec.Struct):
    """A plain Struct inside messages: a map on the wire."""

    x: float
    y: float


class CodecInt(Message):
    v: int


class CodecFloat(Message):
    v: float


class CodecBool(Message):
    v: bool


class CodecStr(Message):
    v: str


class CodecBytes(Message):
    v: bytes


class CodecNone(Message):
    v: None


class CodecUnion(Message):
    v: int | str | None


class CodecLists(Message):
    ints: list[int]
    floats: list[float]
    var: tuple[int, ...]
    pair: tuple[int, str]


class CodecDicts(Message):
    table: dict[str, int]
    of_lists: dict[int, list[str]]
    tuple_keys: dict[tuple[int, int], str]


class CodecBare(Message):
    items: list  # type: ignore[type-arg]
    table: dict  # type: ignore[type-arg]


class CodecEnum(Message):
    v: Color
    many: list[Color]


class CodecPoint(Message):
    x: float
    y: float


class CodecLine(Message):
    start: CodecPoint
    end: CodecPoint


class CodecShapes(Message):
    vec: Vec
    path: list[Vec]
    maybe: CodecPoint | None = None


class CodecNode(Message):
    x: int = 0


class CodecTree(CodecNode):
    child: CodecNode | CodecPoint | None = None


class CodecArray(Message):
    v: np.ndarray  # type: ignore[type-arg]
    typed: npt.NDArray[np.float64] | None = None


class CodecChecked(Message):
    v: int

    def __post_init__(self) -> None:
        if self.v < 0:
            raise ValueError("v must not be negative")


class CodecBounded(Message):
    v: Annotated[int, msgspec.Meta(ge=0, le=9)]


class CodecOutsider(Message):
    """Defined, but not among the messages of CODEC's stack."""

    v: int


ACCEPTED: tuple[type[Message], ...] = (
    CodecInt,
    CodecFloat,
    CodecBool,
    CodecStr,
    CodecBytes,
    CodecNone,
    CodecUnion,
    CodecLists,
    CodecDicts,
    CodecBare,
    CodecEnum,
    CodecPoint,
    CodecLine,
    CodecShapes,
    CodecNode,
    CodecTree,
    CodecArray,
    CodecChecked,
    CodecBounded,
)
LAYERS = 3
CODEC = Codec.for_stack(LAYERS, ACCEPTED)
FP = CODEC.fingerprint
PREFIX = FP.to_bytes(4, "big")
HEADER = b"".join(msgpack.packb(item) for item in (1, 1, 2, 0, 0, 0))  # msg_type, msg_id...
POINT = CodecPoint(1.5, -2.0)


def round_trip(msg: Message, codec: Codec = CODEC) -> Message:
    """``msg`` through the codec, stamped with a message id as the runtime does."""
    sent = msgspec.structs.replace(msg, msg_id=msg.msg_id or 1)
    decoded = codec.decode(codec.encode(sent))
    assert decoded == sent
    return decoded


def raw(cls: type[Message], *fields: bytes) -> bytes:
    """A datagram whose fields are given as raw msgpack (what ``packb`` cannot make)."""
    head = bytes([0x90 + 1 + len(fields) + 6]) + msgpack.packb(tag_of(cls))
    return PREFIX + head + b"".join(fields) + HEADER


def wire(cls: type[Message] | int | str | float, *fields: Any, **header: Any) -> bytes:
    """A datagram of this stack: the tag (or a forged one), the fields, the header."""
    if isinstance(cls, type):
        return datagram(FP, cls, fields, **header)
    return PREFIX + msgpack.packb([cls, *fields, 1, 1, 2, 0, 0, 0])


# --- round trips -------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "msg",
    [
        pytest.param(CodecInt(0), id="int-zero"),
        pytest.param(CodecInt(-(2**63)), id="int-min-int64"),
        pytest.param(CodecInt(2**64 - 1), id="int-max-uint64"),
        pytest.param(CodecFloat(1.25), id="float"),
        pytest.param(CodecFloat(-0.0), id="float-negative-zero"),
        pytest.param(CodecFloat(math.inf), id="float-inf"),
        pytest.param(CodecFloat(5e-324), id="float-subnormal"),
        pytest.param(CodecBool(True), id="bool"),
        pytest.param(CodecStr("héllo ✓ \x00"), id="str-unicode"),
        pytest.param(CodecBytes(bytes(range(256))), id="bytes"),
        pytest.param(CodecNone(None), id="none"),
        pytest.param(CodecUnion(None), id="union-none"),
        pytest.param(CodecUnion(5), id="union-int"),
        pytest.param(CodecUnion("a"), id="union-str"),
        pytest.param(CodecLists([], [], (), (0, "")), id="lists-empty"),
        pytest.param(CodecLists([1, -2], [0.5, -1.0], (1, 2, 3), (1, "a")), id="lists"),
        pytest.param(CodecDicts({}, {}, {}), id="dicts-empty"),
        pytest.param(CodecDicts({"a": 1}, {-2: ["x", ""]}, {(1, 2): "a"}), id="dicts"),
        pytest.param(CodecBare([1, "a", None, 2.5, b"x", [2, [3]], {"k": [True]}], {}), id="bare"),
        pytest.param(CodecBare([], {"a": [1, 2], 3: {"b": b"x"}, None: 1.5}), id="bare-map"),
        pytest.param(CodecEnum(Color.BLUE, [Color.RED, Color.GREEN]), id="int-enum"),
        pytest.param(POINT, id="message-of-floats"),
        pytest.param(CodecLine(POINT, CodecPoint(0.0, 0.0)), id="nested-messages"),
        pytest.param(CodecShapes(Vec(1.0, 2.0), [Vec(3.0, 4.0)], POINT), id="nested-structs"),
        pytest.param(CodecShapes(Vec(1.0, 2.0), []), id="optional-nested-none"),
        pytest.param(CodecTree(1, CodecNode(3)), id="nested-union-of-messages"),
        pytest.param(CodecTree(1, POINT), id="nested-union-other-member"),
        pytest.param(CodecChecked(3), id="post-init-accepts"),
        pytest.param(CodecInt(1, msg_type=MsgType.NEGOTIATION, robot_id=-5, corr_id=9), id="head"),
    ],
)
def test_round_trip_keeps_values_and_types(msg: Message) -> None:
    decoded = round_trip(msg)
    assert type(decoded) is type(msg)
    assert type(decoded.msg_type) is MsgType
    for name in msg.__struct_fields__:
        assert type(getattr(decoded, name)) is type(getattr(msg, name)), name


def test_int_sent_for_a_float_decodes_as_a_float() -> None:
    decoded = round_trip(CodecFloat(3))
    assert isinstance(decoded, CodecFloat)
    assert type(decoded.v) is float
    assert CODEC.decode(wire(CodecFloat, 3)) == CodecFloat(3.0, msg_id=1, robot_id=2)


def test_nan_round_trips_in_an_unbounded_float() -> None:
    decoded = CODEC.decode(CODEC.encode(CodecFloat(math.nan, msg_id=1)))
    assert isinstance(decoded, CodecFloat)
    assert math.isnan(decoded.v)


@pytest.mark.parametrize("buffer", [bytes, bytearray, memoryview])
def test_decode_accepts_any_bytes_like(buffer: Any) -> None:
    assert CODEC.decode(buffer(CODEC.encode(CodecInt(4, msg_id=3)))) == CodecInt(4, msg_id=3)


@pytest.mark.parametrize(
    "array",
    [
        pytest.param(np.array([1.5, -2.0]), id="float64"),
        pytest.param(np.arange(6, dtype=np.float32).reshape(2, 3), id="float32-2d"),
        pytest.param(np.array([1.0, 2.0], dtype=np.float16), id="float16"),
        pytest.param(np.array([True, False]), id="bool"),
        pytest.param(np.array([-128, 127], dtype=np.int8), id="int8"),
        pytest.param(np.array([0, 255], dtype=np.uint8), id="uint8"),
        pytest.param(np.arange(24, dtype=np.int32).reshape(2, 3, 4), id="int32-3d"),
        pytest.param(np.array([2**64 - 1], dtype=np.uint64), id="uint64"),
        pytest.param(np.array([[1 - 1j]], dtype=np.complex128), id="complex128"),
        pytest.param(np.array([1, 2], dtype=">i4"), id="big-endian"),
        pytest.param(np.array(3.5), id="zero-dim"),
        pytest.param(np.zeros((2, 0, 4), dtype=np.int16), id="empty-3d"),
        pytest.param(np.asfortranarray(np.arange(6.0).reshape(2, 3)), id="fortran-order"),
        pytest.param(np.arange(10)[::3], id="strided-view"),
        pytest.param(np.array([math.nan, math.inf]), id="nan-inf"),
    ],
)
def test_numeric_arrays_round_trip_with_dtype_shape_and_bits(array: npt.NDArray[Any]) -> None:
    data = CODEC.encode(CodecArray(array, msg_id=1))
    decoded = CODEC.decode(data)
    assert isinstance(decoded, CodecArray)
    assert (decoded.v.dtype, decoded.v.shape) == (array.dtype, array.shape)
    assert decoded.v.tobytes() == array.tobytes()  # bitwise: NaN compares equal too
    assert decoded.v.flags.writeable  # a normal array, not a view on the datagram
    assert CODEC.decode(data).v is not decoded.v


def test_typed_ndarray_annotation_round_trips() -> None:
    decoded = CODEC.decode(CODEC.encode(CodecArray(np.zeros(1), np.ones((1, 2)), msg_id=1)))
    assert isinstance(decoded, CodecArray)
    assert decoded.typed is not None
    assert decoded.typed.tolist() == [[1.0, 1.0]]


# --- encode errors -----------------------------------------------------------------------------


def test_max_size_below_64_is_refused() -> None:
    with pytest.raises(ValueError, match="at least 64 bytes, got 63"):
        Codec.for_stack(1, ACCEPTED, max_size=63)
    assert Codec.for_stack(1, ACCEPTED, max_size=64).max_size == 64


def test_encode_above_the_limit_names_the_limit() -> None:
    small = Codec.for_stack(LAYERS, ACCEPTED, max_size=64)
    assert small.fingerprint == FP  # the limit is no part of the stack
    assert len(small.encode(CodecBytes(b"x" * 10))) <= 64
    with pytest.raises(
        EncodeError, match=r"CodecBytes encodes to \d+ bytes, above the limit of 64"
    ):
        small.encode(CodecBytes(b"x" * 100))


def loop() -> list[Any]:
    cycle: list[Any] = []
    cycle.append(cycle)
    return cycle


def deep(depth: int) -> list[Any]:
    value: list[Any] = []
    for _ in range(depth):
        value = [value]
    return value


@pytest.mark.parametrize(
    ("msg", "field"),
    [
        pytest.param(CodecBare([object()], {}), "items", id="object"),
        pytest.param(CodecBare([1j], {}), "items", id="complex"),
        pytest.param(CodecBare([], {"k": object()}), "table", id="second-field"),
        pytest.param(CodecInt(2**64), "v", id="int-too-big"),
        pytest.param(CodecInt(-(2**63) - 1), "v", id="int-too-small"),
        pytest.param(CodecStr("\ud800"), "v", id="lone-surrogate"),
        pytest.param(CodecArray(np.array(["text"])), "v", id="ndarray-of-str"),
        pytest.param(CodecArray(np.array([object()])), "v", id="ndarray-of-objects"),
        pytest.param(CodecLine(POINT, CodecPoint(object(), 1.0)), "end", id="inside-nested"),  # type: ignore[arg-type]
        pytest.param(CodecInt(1, msg_id=2**64), "msg_id", id="header"),
        pytest.param(CodecBare(loop(), {}), "items", id="cycle"),
        pytest.param(CodecBare(deep(5000), {}), "items", id="too-deep"),
    ],
)
def test_an_unencodable_value_names_the_field(msg: Message, field: str) -> None:
    with pytest.raises(EncodeError, match=rf"cannot encode {type(msg).__name__}: field '{field}'"):
        CODEC.encode(msg)
    assert CODEC.decode(CODEC.encode(CodecInt(7, msg_id=1))) == CodecInt(7, msg_id=1)


@pytest.mark.parametrize(
    ("msg", "match"),
    [
        pytest.param(
            CodecOutsider(1),
            rf"{__name__}\.CodecOutsider is not among the messages this robot's stack accepts",
            id="not-in-the-stack",
        ),
        pytest.param(Vec(1.0, 2.0), "Vec is not a message", id="plain-struct"),
        pytest.param("text", "str is not a message", id="not-a-struct"),
    ],
)
def test_encoding_what_the_stack_does_not_carry_is_an_encode_error(msg: Any, match: str) -> None:
    with pytest.raises(EncodeError, match=match):
        CODEC.encode(msg)


# --- decode errors: every reason, the field named where there is one ----------------------------

VALID = wire(CodecInt, 1)
OTHER_FP = (FP ^ 0x00FF_FFFF).to_bytes(4, "big")  # another message set, same layer count
PT = [tag_of(CodecPoint), 1.0, 2.0]  # a nested CodecPoint, as encoded (its header left out)


def nd(*value: Any) -> bytes:
    """A CodecArray datagram whose array is ``[dtype, shape, data]`` as given."""
    return wire(CodecArray, list(value), None)


def case(data: bytes, reason: str, match: str, name: str) -> Any:
    return pytest.param(data, reason, match, id=name)


DECODE_ERRORS = [
    # Too long: refused before anything is read.
    case(VALID + b"\0" * 70_000, "oversize", "above the limit of 65536", "oversize"),
    # Not msgpack, or not one value.
    case(b"", "malformed", r"not a datagram \(0 bytes\)", "empty"),
    case(PREFIX[:3], "malformed", r"not a datagram \(3 bytes\)", "shorter-than-the-prefix"),
    case(PREFIX, "malformed", "truncated", "prefix-only"),
    case(PREFIX + b"\xc1", "malformed", "invalid opcode", "never-used-byte"),
    case(VALID[:-1], "malformed", "truncated", "truncated"),
    case(VALID + b"\x00", "malformed", "trailing characters", "trailing-bytes"),
    case(raw(CodecStr, b"\xa2\xff\xfe"), "malformed", "(?i)UTF-8", "bad-utf8"),
    case(b"\xff" * 40, "malformed", r"not a datagram \(40 bytes\)", "garbage"),
    case(OTHER_FP + b"\xc1\x00", "malformed", "not a datagram", "foreign-prefix-garbage"),
    # Not a message array, or a header that is not one.
    case(PREFIX + msgpack.packb(5), "bad_header", "Expected `array`, got `int`", "an-int"),
    case(PREFIX + msgpack.packb({0: 1}), "bad_header", "Expected `array`", "a-map"),
    case(PREFIX + msgpack.packb([]), "bad_header", "length 1, got 0", "empty-array"),
    case(wire(CodecInt, 1, msg_id="x"), "bad_header", r"CodecInt\.msg_id: .*`str`", "id-str"),
    case(wire(CodecInt, 1, msg_id=-1), "bad_header", r"CodecInt\.msg_id: .*>= 0", "id-negative"),
    case(wire(CodecInt, 1, msg_id=0), "bad_header", "CodecInt has no message id", "id-zero"),
    case(wire(CodecInt, 1, msg_type=3), "bad_header", r"msg_type: Invalid enum value 3", "type-3"),
    case(wire(CodecInt, 1, msg_type=1.0), "bad_header", r"msg_type: .*`float`", "type-float"),
    case(wire(CodecInt, 1, robot_id=True), "bad_header", r"robot_id: .*`bool`", "robot-bool"),
    case(wire(CodecInt, 1, src=[]), "bad_header", r"src_layer: .*`array`", "src-array"),
    case(wire(CodecInt, 1, corr_id=None), "bad_header", r"corr_id: .*`None`", "corr-nil"),
    case(wire(CodecInt, 1, header=()), "bad_header", "CodecInt has no message id", "no-header"),
    # A tag this stack does not know.
    case(wire(7, 1), "unknown_type", "unknown message tag: Invalid value 7", "unknown-tag"),
    case(wire("CodecInt", 1), "unknown_type", "unknown message tag: .*`str`", "tag-str"),
    case(wire(float(tag_of(CodecInt)), 1), "unknown_type", "tag: .*`float`", "tag-float"),
    case(wire(CodecOutsider, 1), "unknown_type", str(tag_of(CodecOutsider)), "not-in-the-stack"),
    # Items for the tag, the fields and the header: too few or too many.
    case(wire(CodecInt, header=()), "wrong_arity", "CodecInt: .*1 items for the tag", "tag-only"),
    case(wire(CodecInt, 1, 1, header=(1, 1, 2, 0, 0, 0)), "wrong_arity", "9 items", "one-more"),
    # Field values of the wrong type, the field named.
    case(wire(CodecInt, "x"), "wrong_type", r"CodecInt\.v: .*got `str`", "int-str"),
    case(wire(CodecInt, True), "wrong_type", r"CodecInt\.v: .*got `bool`", "int-bool"),
    case(wire(CodecInt, 1.0), "wrong_type", r"CodecInt\.v: .*got `float`", "int-float"),
    case(wire(CodecBool, 1), "wrong_type", r"CodecBool\.v: .*got `int`", "bool-int"),
    case(wire(CodecStr, b"x"), "wrong_type", r"CodecStr\.v: .*got `bytes`", "str-bytes"),
    case(wire(CodecNone, 0), "wrong_type", r"CodecNone\.v: Expected `null`", "none-int"),
    case(wire(CodecUnion, 1.5), "wrong_type", r"CodecUnion\.v: .*got `float`", "union-float"),
    case(wire(CodecLists, [1, "x"], [], [], [0, ""]), "wrong_type", r"ints\[1\]: ", "list-item"),
    case(wire(CodecLists, [], [], [], [1]), "wrong_type", r"CodecLists\.pair: .*2", "pair"),
    case(wire(CodecDicts, {"a": "b"}, {}, {}), "wrong_type", r"table\[\.\.\.\]: ", "dict-value"),
    case(wire(CodecDicts, {1: 1}, {}, {}), "wrong_type", r"CodecDicts\.table key: ", "dict-key"),
    case(wire(CodecBare, 1, {}), "wrong_type", r"CodecBare\.items: .*`int`", "bare-list-int"),
    case(wire(CodecEnum, 3, []), "wrong_type", r"CodecEnum\.v: Invalid enum value 3", "enum"),
    case(wire(CodecEnum, 1, [1, 4]), "wrong_type", r"CodecEnum\.many\[1\]: ", "enum-item"),
    case(wire(CodecLine, 5, PT), "wrong_type", r"CodecLine\.start: .*`int`", "nested-int"),
    case(wire(CodecLine, [tag_of(CodecInt), 1, 2], PT), "wrong_type", r"start\[0\]", "other-tag"),
    case(wire(CodecLine, [PT[0], "a", 1.0], PT), "wrong_type", r"start\[1\]: ", "nested-field"),
    case(wire(CodecShapes, {"x": 1.0}, []), "wrong_type", r"CodecShapes\.vec: .*`y`", "struct"),
    case(
        wire(CodecShapes, {"x": 1.0, "y": 2.0}, [{"x": 1.0, "y": None}]),
        "wrong_type",
        r"CodecShapes\.path\[0\]\.y: ",
        "struct-in-list",
    ),
    case(wire(CodecArray, 5, None), "wrong_type", r"CodecArray\.v: .*ndarray", "nd-int"),
    case(nd("|O", [1], b"\0" * 8), "wrong_type", r"CodecArray\.v: .*numeric dtype", "nd-object"),
    case(nd("<f8", [2], b"\0" * 15), "wrong_type", "does not match 15 bytes", "nd-short"),
    case(nd("<f8", [10**9], b"\0" * 8), "wrong_type", "does not match 8 bytes", "nd-huge"),
    case(nd("<f8", [1] * 33, b"\0" * 8), "wrong_type", "at most 32 dimensions", "nd-dims"),
    case(nd("<f8", [-1], b""), "wrong_type", "non-negative", "nd-negative"),
    case(nd("<f8", [0, 2**62, 2**62], b""), "wrong_type", "bad shape", "nd-empty-huge"),
    case(
        wire(CodecChecked, -1), "wrong_type", "^CodecChecked: v must not be negative", "post-init"
    ),
    # A value its type allows and its bounds do not.
    case(wire(CodecBounded, 10), "out_of_range", r"CodecBounded\.v: .*<= 9", "above"),
    case(wire(CodecBounded, -1), "out_of_range", r"CodecBounded\.v: .*>= 0", "below"),
]


@pytest.mark.parametrize(("data", "reason", "match"), DECODE_ERRORS)
def test_decode_error_reason(data: bytes, reason: str, match: str) -> None:
    with pytest.raises(DecodeError, match=match) as caught:
        CODEC.decode(data)
    assert caught.value.reason == reason
    assert type(caught.value) is DecodeError


def test_every_reason_is_in_the_table() -> None:
    reasons = {param.values[1] for param in DECODE_ERRORS} | {"stack_mismatch"}  # below
    assert reasons == set(DecodeError.REASONS)


def test_a_datagram_of_another_stack_is_a_stack_mismatch_with_both_fingerprints() -> None:
    theirs = Codec.for_stack(LAYERS + 1, ACCEPTED)
    with pytest.raises(StackMismatchError) as caught:
        CODEC.decode(theirs.encode(CodecInt(1, msg_id=1)))
    error = caught.value
    assert error.reason == "stack_mismatch"
    assert isinstance(error, DecodeError)
    assert (error.theirs, error.ours) == (theirs.fingerprint, FP)
    assert describe_fingerprint(theirs.fingerprint) in str(error)
    assert describe_fingerprint(FP) in str(error)
    # Before anything else is looked at: a foreign prefix on a forged array is a mismatch too.
    with pytest.raises(StackMismatchError):
        CODEC.decode(OTHER_FP + msgpack.packb([7, "x"]))


@pytest.mark.parametrize("depth", [1000, 5000, 30_000], ids=lambda d: f"depth-{d}")
@pytest.mark.parametrize("link", [b"\x91", b"\x81\x00"], ids=["arrays", "maps"])
def test_deep_nesting_is_a_decode_error_not_a_recursion_error(depth: int, link: bytes) -> None:
    with pytest.raises(DecodeError) as caught:
        CODEC.decode(raw(CodecBare, link * depth + b"\x00", b"\x80"))
    assert caught.value.reason in {"wrong_type", "malformed"}
