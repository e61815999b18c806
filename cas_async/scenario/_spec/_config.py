"""TOML tables into frozen dataclasses, with errors that say where and what was expected.

An application declares each section of its scenario file as a frozen dataclass
whose fields use :func:`setting` for their default, bounds and a short doc::

    @dataclass(frozen=True)
    class Robots:
        count: int = setting(10, ge=1, doc="robots in the swarm")
        speed: float = setting(5.0, gt=0, doc="full speed, distance units per second")

:func:`from_toml` reads a TOML table into such a class. It checks every key
before giving up, so a scenario's mistakes are all reported at once, each as
``key: message`` in one :class:`ScenarioError`.

Field types read: ``bool``, ``int``, ``float`` (an integer is accepted; nan and
infinities are not), ``str``, ``Literal[...]``, fixed-length tuples such as
``tuple[float, float]``, ``tuple[X, ...]`` and ``list[X]`` (TOML arrays),
nested dataclasses (sub-tables), arrays of them (arrays of tables), and
``X | None``. TOML has no null, so ``None`` can only be a default. Bounds apply
to numbers, including each number of an array. Array indices in keys count
from 0 (``generators[1]`` is the second ``[[generators]]`` table).
"""

from __future__ import annotations

import dataclasses
import datetime
import difflib
import functools
import json
import math
import types
from collections.abc import Collection, Mapping, Sequence
from typing import (
    Annotated,
    Any,
    Final,
    Literal,
    TypeVar,
    Union,
    get_args,
    get_origin,
    get_type_hints,
)

import msgspec

from ..._errors import ConfigurationError

__all__ = ["ScenarioError", "from_toml", "setting", "show"]

T = TypeVar("T")

_BOUNDS: Final = "cas_async.bounds"
_INVALID: Final = object()  # a value that failed; its problem is already recorded
_SHOW_LIMIT: Final = 60
_NUMBERS: Final = (int, float)
# How a TOML value of each scalar type is named: one of them, several of them.
_NAMES: Final[dict[Any, tuple[str, str]]] = {
    bool: ("true or false", "booleans"),
    int: ("an integer", "integers"),
    float: ("a number", "numbers"),
    str: ("a string", "strings"),
}

_Problems = list[tuple[str, str]]


class ScenarioError(ConfigurationError):
    """A scenario is not valid; carries every problem found, each naming its key.

    ``str()`` gives one line per problem, ``file: key: message``, leaving out
    the file when it is not known and the key when the problem is the file's.

    Attributes:
        problems: ``(key, message)`` pairs; ``key`` is a dotted path such as
            ``"robots.speed"`` or ``"generators[1].rate"``, or ``""`` for the whole file.
        file: the scenario file as given, or ``None`` when not (yet) known.
    """

    def __init__(self, problems: Sequence[tuple[str, str]], file: str | None = None) -> None:
        self.problems: tuple[tuple[str, str], ...] = tuple(problems)
        self.file = file
        super().__init__(
            "\n".join(
                ": ".join(part for part in (file, key, message) if part)
                for key, message in self.problems
            )
        )

    def __reduce__(self) -> tuple[Any, ...]:
        return type(self), (self.problems, self.file)

    def with_file(self, file: str) -> ScenarioError:
        """The same problems, reported against ``file``."""
        return type(self)(self.problems, file)


@dataclasses.dataclass(frozen=True, slots=True)
class _Bounds:
    """A setting's bounds, as a ``msgspec.Meta`` states them (messages state theirs so too)."""

    meta: msgspec.Meta

    def admit(self, value: float) -> bool:
        meta = self.meta
        return (
            (meta.ge is None or value >= meta.ge)
            and (meta.gt is None or value > meta.gt)
            and (meta.le is None or value <= meta.le)
            and (meta.lt is None or value < meta.lt)
        )

    def __str__(self) -> str:
        meta = self.meta
        limits = ((">=", meta.ge), (">", meta.gt), ("<=", meta.le), ("<", meta.lt))
        return " and ".join(f"{op} {show(bound)}" for op, bound in limits if bound is not None)


_NO_BOUNDS: Final = _Bounds(msgspec.Meta())


def _bounds_of(field: dataclasses.Field[Any], hint: Any) -> tuple[Any, _Bounds]:
    """The field's type without its ``Annotated`` bounds, and the bounds of both ways.

    A setting's bounds are written ``setting(3.0, gt=0)``, or in its annotation as
    a message field's are: ``Annotated[float, msgspec.Meta(gt=0)]``.
    """
    metas = [field.metadata[_BOUNDS]] if _BOUNDS in field.metadata else []
    if get_origin(hint) is Annotated:
        hint, *extras = get_args(hint)
        metas += [extra for extra in extras if isinstance(extra, msgspec.Meta)]
    limits: dict[str, Any] = {}
    for meta in metas:
        for name in ("ge", "gt", "le", "lt"):
            value = getattr(meta, name)
            if value is not None:
                if name in limits:
                    raise TypeError(f"{field.name}: bound {name} given twice")
                limits[name] = value
    return hint, _Bounds(msgspec.Meta(**limits)) if limits else _NO_BOUNDS


def setting(
    default: Any = dataclasses.MISSING,
    *,
    default_factory: Any = dataclasses.MISSING,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    doc: str = "",
) -> Any:
    """A dataclass field for a scenario setting, with bounds and a doc.

    Without ``default`` or ``default_factory`` the key is required.

    Args:
        default: the value when the key is absent.
        default_factory: makes the value when the key is absent (for tables, lists).
        ge: numbers must be ``>= ge``.
        gt: numbers must be ``> gt``.
        le: numbers must be ``<= le``.
        lt: numbers must be ``< lt``.
        doc: one line on what the setting means, in its units; kept in the
            field's ``metadata["doc"]``.

    Returns:
        A ``dataclasses.field`` for :func:`from_toml` to read.

    Raises:
        ValueError: both ``default`` and ``default_factory`` are given.
    """
    limits: dict[str, Any] = {"ge": ge, "gt": gt, "le": le, "lt": lt}
    meta = msgspec.Meta(**{name: value for name, value in limits.items() if value is not None})
    metadata = {"doc": doc, _BOUNDS: meta}
    return dataclasses.field(default=default, default_factory=default_factory, metadata=metadata)


def from_toml(
    cls: type[T], data: Mapping[str, Any], *, key: str = "", others: Collection[str] = ()
) -> T:
    """Reads a TOML table (as ``tomllib`` returns it) into the dataclass ``cls``.

    Args:
        cls: a dataclass whose fields have the types listed in the module docs.
        data: the table.
        key: where the table sits in the file (``"robots"``), prefixed to the
            keys of problems; ``""`` for the top level.
        others: keys of ``data`` that are not fields of ``cls`` but are read
            elsewhere: not reported as unknown, and listed among the expected
            keys when suggesting a fix for an unknown one.

    Raises:
        ScenarioError: with every problem found (unknown or missing keys, wrong
            types, values out of bounds); its ``file`` is ``None``.
        TypeError: ``cls`` is not a dataclass or has a field of a type not read.
    """
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)):
        raise TypeError(f"from_toml needs a dataclass, got {cls!r}")
    problems: _Problems = []
    result = _table(cls, data, key, problems, others)
    if problems:
        raise ScenarioError(problems)
    return result  # type: ignore[no-any-return]


@functools.cache
def _fields(cls: type[Any]) -> tuple[tuple[str, Any, _Bounds, bool], ...]:
    """``(name, type, bounds, required)`` of each field set by ``__init__``."""
    hints = get_type_hints(cls, include_extras=True)
    return tuple(
        (
            field.name,
            *_bounds_of(field, hints[field.name]),
            field.default is dataclasses.MISSING and field.default_factory is dataclasses.MISSING,
        )
        for field in dataclasses.fields(cls)
        if field.init
    )


def _table(
    cls: Any, data: object, key: str, problems: _Problems, others: Collection[str] = ()
) -> Any:
    if not isinstance(data, Mapping):
        problems.append((key, _wrong("a table", data)))
        return _INVALID
    before = len(problems)
    fields = _fields(cls)
    known = sorted({name for name, *_ in fields}.union(others))
    problems.extend((key, _unknown(name, known)) for name in data if name not in known)
    values = {}
    for name, hint, bounds, required in fields:
        where = f"{key}.{name}" if key else name
        if name in data:
            values[name] = _value(hint, bounds, data[name], where, problems)
        elif required:
            problems.append((where, f"missing required key (expected {_expected(hint, bounds)})"))
    return cls(**values) if len(problems) == before else _INVALID


def _value(hint: Any, bounds: _Bounds, value: object, key: str, problems: _Problems) -> Any:
    origin, args = get_origin(hint), get_args(hint)
    if origin is Union or origin is types.UnionType:
        return None if value is None else _value(_optional(hint), bounds, value, key, problems)
    if origin is Literal:
        return _choice(args, value, key, problems)
    if origin is tuple or origin is list:
        return _array(hint, bounds, value, key, problems)
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        return _table(hint, value, key, problems)
    if hint in _NAMES:
        return _scalar(hint, bounds, value, key, problems)
    raise TypeError(f"{key or 'a setting'}: a field of type {hint!r} cannot be read from TOML")


def _optional(hint: Any) -> Any:
    """``X`` of ``X | None``; other unions are not read."""
    arms = [arm for arm in get_args(hint) if arm is not type(None)]
    if len(arms) != 1:
        raise TypeError(f"a field of type {hint!r} cannot be read from TOML (only X | None)")
    return arms[0]


def _scalar(hint: type, bounds: _Bounds, value: object, key: str, problems: _Problems) -> Any:
    # bool is an int in Python, but true is not a number in TOML.
    fits = isinstance(value, hint) and (hint is bool or not isinstance(value, bool))
    if hint is float and isinstance(value, int) and not isinstance(value, bool):
        fits = True
    if not fits:
        problems.append((key, _wrong(_expected(hint, bounds), value)))
        return _INVALID
    if hint in _NUMBERS:
        assert isinstance(value, int | float)
        if not (math.isfinite(value) and bounds.admit(value)):
            note = "" if math.isfinite(value) else " (not finite)"
            problems.append((key, f"expected {_expected(hint, bounds)}, got {show(value)}{note}"))
            return _INVALID
        return hint(value)
    return value


def _choice(choices: tuple[Any, ...], value: object, key: str, problems: _Problems) -> Any:
    for choice in choices:
        # 1 == True in Python; a TOML choice must match in type as well.
        if type(choice) is type(value) and choice == value:
            return choice
    expected = "one of " + ", ".join(show(choice) for choice in choices)
    if not isinstance(value, str):
        problems.append((key, _wrong(expected, value)))
        return _INVALID
    words = [choice for choice in choices if isinstance(choice, str)]
    close = difflib.get_close_matches(value, words, n=1)
    hint = f" (did you mean {show(close[0])}?)" if close else ""
    problems.append((key, f"expected {expected}, got {show(value)}{hint}"))
    return _INVALID


def _array(hint: Any, bounds: _Bounds, value: object, key: str, problems: _Problems) -> Any:
    if not isinstance(value, list | tuple):
        problems.append((key, _wrong(_expected(hint, bounds), value)))
        return _INVALID
    args = get_args(hint)
    variadic = get_origin(hint) is list or args[-1:] == (Ellipsis,)
    if variadic:
        args = args[:1] * len(value)
    elif len(value) != len(args):
        count = f"{len(value)} item{'' if len(value) == 1 else 's'}"
        problems.append((key, f"expected {_expected(hint, bounds)}, got {show(value)} ({count})"))
        return _INVALID
    before = len(problems)
    items = [
        _value(arm, bounds, item, f"{key}[{index}]", problems)
        for index, (arm, item) in enumerate(zip(args, value, strict=True))
    ]
    if len(problems) > before:
        return _INVALID
    return items if get_origin(hint) is list else tuple(items)


def _expected(hint: Any, bounds: _Bounds = _NO_BOUNDS) -> str:
    """What a value of type ``hint`` looks like in TOML, e.g. ``a number > 0``."""
    origin, args = get_origin(hint), get_args(hint)
    if origin is Union or origin is types.UnionType:
        return _expected(_optional(hint), bounds)
    if origin is Literal:
        return "one of " + ", ".join(show(choice) for choice in args)
    if origin is tuple or origin is list:
        if origin is list or args[-1:] == (Ellipsis,):
            return f"an array of {_noun(args[0], bounds, plural=True)}"
        same = all(arm == args[0] for arm in args)
        many = _noun(args[0], bounds, plural=True) if same else "values"
        return f"an array of {len(args)} {many}"
    return _noun(hint, bounds)


def _noun(hint: Any, bounds: _Bounds, *, plural: bool = False) -> str:
    """``a number > 0``, or ``numbers > 0`` when ``plural``; arrays are described above."""
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        return "tables" if plural else "a table"
    one, many = _NAMES.get(hint, (repr(hint), "values"))
    text = many if plural else one
    return f"{text} {bounds}" if hint in _NUMBERS and bounds != _NO_BOUNDS else text


def _unknown(name: str, known: list[str]) -> str:
    if not known:
        return f"unknown key {name!r} (this table takes no keys)"
    close = difflib.get_close_matches(name, known, n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    return f"unknown key {name!r} ({hint}expected one of: {', '.join(known)})"


def _wrong(expected: str, value: object) -> str:
    return f"expected {expected}, got {show(value)} ({_kind(value)})"


def _kind(value: object) -> str:
    kinds: tuple[tuple[Any, str], ...] = (
        (bool, "a boolean"),
        (int, "an integer"),
        (float, "a float"),
        (str, "a string"),
        (Mapping, "a table"),
        (list | tuple, "an array"),
        (datetime.date | datetime.time, "a date or time"),
    )
    return next((kind for cls, kind in kinds if isinstance(value, cls)), type(value).__name__)


def show(value: object) -> str:
    """``value`` as it would be written in TOML, cut short if long."""
    text = _toml(value)
    return text if len(text) <= _SHOW_LIMIT else text[: _SHOW_LIMIT - 1] + "…"


def _toml(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # TOML basic strings escape alike
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{key} = {_toml(item)}" for key, item in value.items()) + "}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml(item) for item in value) + "]"
    if isinstance(value, datetime.date | datetime.time):
        return value.isoformat()
    return repr(value)
