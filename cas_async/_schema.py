"""Field types of messages: from annotations to wire checks.

Every message field is declared with a type annotation. At ``@message`` time each
annotation is turned into a :class:`FieldType`, which knows:

* how to *check and convert* a value that came off the wire (msgpack decodes with
  ``use_list=False``, so arrays arrive as tuples) into the declared Python type,
  raising :class:`~cas_async._errors.DecodeError` with the field's path;
* a *fast check*, an expression over ``{v}`` the code generator inlines when the
  wire value needs no conversion (``type(v) is int``), so the common case costs
  one comparison instead of a function call;
* a canonical text used by the stack fingerprint.

Supported: ``int``, ``float``, ``bool``, ``str``, ``bytes``, ``None``, unions of
those (``X | None``), ``list[T]``, ``tuple[T, ...]``, ``tuple[A, B]``,
``dict[K, V]``, bare ``list``/``tuple``/``dict`` of plain values, ``IntEnum``
subclasses, ``numpy.ndarray`` (numeric dtypes) and nested messages.
"""

from __future__ import annotations

import enum
import functools
import operator
import re
import sys
import types
import typing
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Annotated, Any, Final

import msgspec
import numpy as np

from ._bounds import Bounds
from ._errors import DecodeError, MessageDefinitionError

__all__ = ["FieldType", "NestedMessages", "field_type", "shown"]

Convert = Callable[[Any, str], Any]
"""Checks a wire value and returns it as the declared type; ``str`` is the path."""

# Array dtypes accepted off the wire: booleans, integers, floats, complex numbers.
# Object, string and void dtypes are refused (object arrays would mean pickle).
_NUMERIC_KINDS: Final = frozenset("biufc")
_MAX_NDIM: Final = 32
# What ndarray_to_wire writes (``array.dtype.str``): byte order, kind, item size. Anything
# else is refused before numpy parses it (numpy accepts, and warns about, many aliases).
_DTYPE_TEXT: Final = re.compile(r"[<>|=]?[biufc][0-9]{1,2}")
_SHOWN_CHARS: Final = 60
"""Characters of a value off the wire quoted in an error message at most."""
_PATH_ENDS: Final = 8
"""Steps of a long path shown at each end in an error message."""


@dataclass(frozen=True, slots=True)
class FieldType:
    """How one declared type is checked, converted and described."""

    text: str
    convert: Convert
    fast_check: str | None = None
    exact: type | None = None
    """Set when wire values of this type are used as they are (``int``, ``str``...)."""
    container: type | None = None
    """``list`` or ``tuple`` for ``list[T]`` / ``tuple[T, ...]`` whose elements are used
    as they are; ``elements`` is then their type, and decoders inline the check."""
    elements: type | None = None
    wire: Any = None
    """The type msgspec checks wire values against, exactly as ``convert`` would accept
    them, or None when only ``convert`` can (see :mod:`cas_async._codegen`)."""
    scalar: bool = False
    """Whether wire values are never arrays or maps (numbers, text, bytes, None...)."""


def shown(value: Any) -> str:
    """A short ``repr`` of a value off the wire, for error messages and field paths.

    Untrusted values may be 64 KiB strings or arrays nested 1000 deep, whose full
    ``repr`` is large or raises ``RecursionError``: arrays and maps are described
    by their length only, and long texts are cut.
    """
    kind = type(value)
    if kind is tuple:
        return f"<array of {len(value)}>"
    if kind is dict:
        return f"<map of {len(value)}>"
    if kind is str or kind is bytes:
        text = repr(value[:_SHOWN_CHARS])
        return text if len(value) <= _SHOWN_CHARS else f"{text}..."
    if kind in (int, float, bool) or value is None:
        return repr(value)  # at most 20 digits: msgpack integers are 64-bit
    return f"<{kind.__name__}>"  # ExtType, Timestamp


def _describe(value: Any) -> str:
    return "array" if type(value) is tuple else type(value).__name__  # not ExtType


def _fail(path: str, expected: str, value: Any) -> DecodeError:
    return DecodeError(f"{path}: expected {expected}, got {_describe(value)}", "wrong_type")


def _exact(kind: type, name: str) -> FieldType:
    def convert(value: Any, path: str) -> Any:
        if type(value) is kind:
            return value
        raise _fail(path, name, value)

    return FieldType(name, convert, f"type({{v}}) is {name}", kind, wire=kind, scalar=True)


def _float_convert(value: Any, path: str) -> float:
    kind = type(value)
    if kind is float:
        return value  # type: ignore[no-any-return]
    if kind is int:
        return float(value)  # senders may write 3 for 3.0; msgpack then sends an int
    raise _fail(path, "float", value)


def _none_convert(value: Any, path: str) -> None:
    if value is not None:
        raise _fail(path, "None", value)


_SIMPLE: Final[dict[Any, FieldType]] = {
    int: _exact(int, "int"),
    bool: _exact(bool, "bool"),
    str: _exact(str, "str"),
    bytes: _exact(bytes, "bytes"),
    # msgspec, like _float_convert, accepts an int for a float and returns a float.
    float: FieldType("float", _float_convert, "type({v}) is float", wire=float, scalar=True),
    type(None): FieldType("None", _none_convert, "{v} is None", wire=type(None), scalar=True),
    None: FieldType("None", _none_convert, "{v} is None", wire=type(None), scalar=True),
}


class _NotPlain(Exception):
    """Raised inside a bare container; ``steps`` collects the path while unwinding."""

    def __init__(self, expected: str, value: Any) -> None:
        super().__init__(expected)
        self.expected = expected
        self.value = value
        self.steps: list[str] = []


def _plain_convert(value: Any, path: str) -> Any:
    """Any msgpack-native value; arrays become lists (for bare ``list``/``dict``)."""
    try:
        return _plain(value)
    except _NotPlain as exc:
        steps = exc.steps[::-1]
        if len(steps) > 2 * _PATH_ENDS:  # keep the message short, whatever the depth
            hidden = len(steps) - 2 * _PATH_ENDS
            steps[_PATH_ENDS:-_PATH_ENDS] = [f"...{hidden} levels..."]
        raise _fail(path + "".join(steps), exc.expected, exc.value) from None


def _plain(value: Any) -> Any:
    # The path of an error is only built if there is one (on the way out): bare
    # containers nest as deep as msgpack allows, and a path per level, each
    # quoting the keys above it, would grow with the square of the depth.
    kind = type(value)
    if kind in (int, float, bool, str, bytes) or value is None:
        return value
    if kind is tuple:
        items = []
        for i, item in enumerate(value):
            try:
                items.append(_plain(item))
            except _NotPlain as exc:
                exc.steps.append(f"[{i}]")
                raise
        return items
    if kind is dict:
        # Converted in place: a copy would double what a map-heavy datagram costs,
        # and the dict is the unpacker's own (when this fails, the whole field does).
        for key, item in value.items():
            if not (type(key) in (int, float, bool, str, bytes) or key is None):
                failure = _NotPlain("a plain key", key)
                failure.steps.append(" key")
                raise failure
            try:
                converted = _plain(item)
            except _NotPlain as exc:
                exc.steps.append(f"[{shown(key)}]")
                raise
            if converted is not item:
                value[key] = converted  # an existing key: iterating on is safe
        return value
    raise _NotPlain("a plain value", value)


def _plain_key(key: Any, path: str) -> Any:
    if type(key) in (int, float, bool, str, bytes) or key is None:
        return key
    raise _fail(path, "a plain key", key)


def _sequence(item: FieldType, make: Callable[[Any], Any], name: str) -> Convert:
    item_convert = item.convert
    exact = item.exact
    if exact is not None:
        # Elements need no conversion: check them all, build the container once.
        def convert_fast(value: Any, path: str) -> Any:
            if type(value) is not tuple:
                raise _fail(path, name, value)
            for element in value:
                if type(element) is not exact:
                    break
            else:
                return make(value)
            return make(item_convert(e, f"{path}[{i}]") for i, e in enumerate(value))

        return convert_fast

    def convert(value: Any, path: str) -> Any:
        if type(value) is not tuple:
            raise _fail(path, name, value)
        return make(item_convert(element, f"{path}[{i}]") for i, element in enumerate(value))

    return convert


def _fixed_tuple(items: tuple[FieldType, ...], name: str) -> Convert:
    def convert(value: Any, path: str) -> tuple[Any, ...]:
        if type(value) is not tuple or len(value) != len(items):
            raise _fail(path, name, value)
        return tuple(
            item.convert(v, f"{path}[{i}]")
            for i, (item, v) in enumerate(zip(items, value, strict=True))
        )

    return convert


def _mapping(key: FieldType, val: FieldType, name: str) -> Convert:
    def convert(value: Any, path: str) -> dict[Any, Any]:
        if type(value) is not dict:
            raise _fail(path, name, value)
        try:
            return {
                key.convert(k, f"{path} key"): val.convert(v, f"{path}[{shown(k)}]")
                for k, v in value.items()
            }
        except TypeError:  # a converted key is unhashable (e.g. dict[list[int], ...])
            raise DecodeError(f"{path}: unhashable key", "wrong_type") from None

    return convert


def _union(options: tuple[FieldType, ...], name: str) -> FieldType:
    plain = [o for o in options if o.text != "None"]
    optional = plain[0] if len(options) == 2 and len(plain) == 1 else None

    def convert(value: Any, path: str) -> Any:
        if optional is not None and value is not None:
            try:
                return optional.convert(value, path)
            except DecodeError as exc:
                # ``T | None``: an error inside the value (an element, a bound) is T's
                # own, more precise; a value of another type is told as the union's.
                if exc.reason != "wrong_type" or not str(exc).startswith(f"{path}: "):
                    raise
                raise _fail(path, name, value) from None
        for option in options:
            try:
                return option.convert(value, path)
            except DecodeError:
                continue
        raise _fail(path, name, value)

    fast = None
    if all(o.fast_check is not None and o.text != "float" for o in options):
        fast = (
            "(" + " or ".join(o.fast_check.format(v="{v}") for o in options if o.fast_check) + ")"
        )
    wire: Any = None
    if optional is not None and optional.wire is not None:
        wire = optional.wire | None  # only ``T | None``: msgspec's other unions differ
    scalar = all(option.scalar for option in options)
    return FieldType(name, convert, fast, wire=wire, scalar=scalar)


def _int_enum(kind: type[enum.IntEnum]) -> FieldType:
    name = kind.__name__
    members = {int(member): member for member in kind}

    def convert(value: Any, path: str) -> enum.IntEnum:
        if type(value) is int and value in members:
            return members[value]
        raise _fail(path, f"{name} (one of {sorted(members)})", value)

    return FieldType(f"{name}{sorted(members)}", convert, wire=kind, scalar=True)


def _shown_shape(shape: tuple[Any, ...]) -> str:
    """A refused shape, for its error message (it may hold anything, at any length)."""
    if len(shape) > _MAX_NDIM:
        return shown(shape)
    return f"[{', '.join(map(shown, shape))}]"


def _ndarray_convert(value: Any, path: str) -> np.ndarray[Any, Any]:
    # Nothing is allocated for the array until the bytes present are exactly what
    # the dtype and shape need: a datagram claiming 10**9 elements costs nothing.
    if type(value) is not tuple or len(value) != 3:
        raise _fail(path, "ndarray [dtype, shape, data]", value)
    dtype_text, shape, data = value
    if type(dtype_text) is not str or type(shape) is not tuple or type(data) is not bytes:
        raise _fail(path, "ndarray [dtype, shape, data]", value)
    if _DTYPE_TEXT.fullmatch(dtype_text) is None:
        raise DecodeError(
            f"{path}: dtype {shown(dtype_text)} is not a numeric dtype code like '<f8'",
            "wrong_type",
        )
    try:
        dtype = np.dtype(dtype_text)
    except TypeError:
        raise DecodeError(f"{path}: unknown dtype {dtype_text!r}", "wrong_type") from None
    if len(shape) > _MAX_NDIM or not all(type(n) is int and n >= 0 for n in shape):
        raise DecodeError(f"{path}: bad shape {_shown_shape(shape)}", "wrong_type")
    count = 1
    for n in shape:
        count *= n
    needed = count * dtype.itemsize
    if needed != len(data):
        amount = needed if needed < 2**64 else "over 2**64"  # 32 dims: a 600-digit number
        raise DecodeError(
            f"{path}: shape {shape!r} of {dtype_text} needs {amount} bytes, got {len(data)}",
            "wrong_type",
        )
    try:
        # copy(): frombuffer over bytes is read-only; users expect a normal array.
        return np.frombuffer(data, dtype=dtype).reshape(shape).copy()
    except ValueError:  # e.g. shape (0, 2**62, 2**62): no data, but too big for numpy
        raise DecodeError(f"{path}: bad shape {shape!r}", "wrong_type") from None


def ndarray_to_wire(array: np.ndarray[Any, Any]) -> tuple[str, tuple[int, ...], bytes]:
    """Encodes a numeric array as ``(dtype, shape, C-order bytes)``."""
    if array.dtype.kind not in _NUMERIC_KINDS:
        raise TypeError(f"cannot send an array of dtype {array.dtype} (only numeric dtypes)")
    return array.dtype.str, array.shape, array.tobytes()


@dataclass(frozen=True, slots=True)
class NestedMessages:
    """How fields holding messages are recognised and decoded (the registry owns both).

    Attributes:
        base: the message base class: a field annotated with a subclass nests a message.
        decode: ``decode(value, path, expected_class)`` of a nested message off the wire.
    """

    base: type
    decode: Callable[[Any, str, type], Any]


def _nested_message(kind: type, nested: NestedMessages) -> FieldType:
    decode = nested.decode

    def convert(value: Any, path: str) -> Any:
        return decode(value, path, kind)

    return FieldType(kind.__name__, convert)


def _bounded(kind: FieldType, bounds: Bounds, where: str) -> FieldType:
    """``kind`` (an ``int`` or ``float``) whose values must also be within ``bounds``."""
    if kind.text not in ("int", "float"):
        raise MessageDefinitionError(
            f"{where}: Bounds apply to int and float fields, not to {kind.text}"
        )
    if bounds.finite and kind.text == "int":
        bounds = replace(bounds, finite=False)  # every int is finite
    inner, text = kind.convert, f"{kind.text}({bounds.text})"

    def convert(value: Any, path: str) -> Any:
        number = inner(value, path)
        if bounds.admits(number):
            return number
        raise DecodeError(f"{path}: expected {text}, got {shown(number)}", "out_of_range")

    # msgspec checks the same bounds in C (finite: within the largest floats; any
    # bound refuses NaN there too).
    most = sys.float_info.max if bounds.finite else None
    limits: dict[str, Any] = {
        "ge": bounds.ge if bounds.ge is not None else (None if most is None else -most),
        "gt": bounds.gt,
        "le": bounds.le if bounds.le is not None else most,
        "lt": bounds.lt,
    }
    meta = msgspec.Meta(**{name: value for name, value in limits.items() if value is not None})
    return FieldType(text, convert, wire=Annotated[kind.wire, meta], scalar=True)


def field_type(annotation: Any, where: str, nested: NestedMessages) -> FieldType:
    """Builds the :class:`FieldType` of an annotation, or explains why it is unsupported."""
    if annotation in _SIMPLE:
        return _SIMPLE[annotation]
    if typing.get_origin(annotation) is Annotated:
        base, *extras = typing.get_args(annotation)
        kind = field_type(base, where, nested)
        found = [extra for extra in extras if isinstance(extra, Bounds)]
        return kind if not found else _bounded(kind, functools.reduce(operator.and_, found), where)
    if annotation is list:
        return FieldType("list", _sequence(FieldType("plain", _plain_convert), list, "list"))
    if annotation is tuple:
        return FieldType("tuple", _sequence(FieldType("plain", _plain_convert), tuple, "tuple"))
    if annotation is dict:
        plain = FieldType("plain", _plain_convert)
        return FieldType("dict", _mapping(FieldType("key", _plain_key), plain, "dict"))
    if annotation is np.ndarray:
        return FieldType("ndarray", _ndarray_convert)
    if isinstance(annotation, type):
        if issubclass(annotation, enum.IntEnum):
            return _int_enum(annotation)
        if issubclass(annotation, nested.base):
            return _nested_message(annotation, nested)
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if origin is np.ndarray:  # numpy.typing.NDArray[...]
        return FieldType("ndarray", _ndarray_convert)
    if origin in (typing.Union, types.UnionType):
        options = tuple(field_type(a, where, nested) for a in args)
        return _union(options, " | ".join(o.text for o in options))
    if origin is list and len(args) == 1:
        item = field_type(args[0], where, nested)
        name = f"list[{item.text}]"
        container: type | None = list if item.exact is not None else None
        wire: Any = None if item.wire is None else list[item.wire]  # type: ignore[name-defined]
        convert = _sequence(item, list, name)
        return FieldType(name, convert, None, None, container, item.exact, wire)
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        item = field_type(args[0], where, nested)
        name = f"tuple[{item.text}, ...]"
        container_t: type | None = tuple if item.exact is not None else None
        wire = None if item.wire is None else tuple[item.wire, ...]  # type: ignore[name-defined]
        convert = _sequence(item, tuple, name)
        return FieldType(name, convert, None, None, container_t, item.exact, wire)
    if origin is tuple and args:
        items = tuple(field_type(a, where, nested) for a in args)
        name = f"tuple[{', '.join(i.text for i in items)}]"
        return FieldType(name, _fixed_tuple(items, name))
    if origin is dict and len(args) == 2:
        key, val = (field_type(a, where, nested) for a in args)
        name = f"dict[{key.text}, {val.text}]"
        return FieldType(name, _mapping(key, val, name))
    raise MessageDefinitionError(
        f"{where}: unsupported field type {annotation!r}; use int, float, bool, str, bytes, "
        "None, list/tuple/dict of those, an IntEnum, numpy.ndarray or another message"
    )
