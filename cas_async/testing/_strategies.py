"""Hypothesis strategies of messages, made from msgspec's description of their fields."""

from __future__ import annotations

import typing
from typing import Any

import msgspec.inspect as mi
import numpy as np

from .. import Message, message_fields

if typing.TYPE_CHECKING:
    from hypothesis.strategies import SearchStrategy

__all__ = ["strategy_for"]

_INT64: typing.Final = (-(2**63), 2**63 - 1)
"""The ints every field carries (msgpack's signed 64 bits)."""
_MAX_ITEMS: typing.Final = 6
"""Items per generated list, tuple or dict: enough to find shapes, few enough to stay fast."""


def strategy_for(cls: type[Message]) -> SearchStrategy[Any]:
    """A Hypothesis strategy of ``cls`` messages, every field drawn from its type.

    Fields follow their types, bounds included (``Annotated[float, Finite]`` draws
    no NaN, ``msgspec.Meta(ge=0)`` nothing below 0; unbounded floats draw NaN and
    infinities too); nested structs and messages, enums, optional fields, lists,
    tuples, dicts and numpy arrays are drawn in kind. Headers are left unset. For
    example::

        @given(strategy_for(Meet))
        def test_meet_survives_the_codec(meet: Meet) -> None:
            assert_roundtrip(meet, messages=MESSAGES)

    Raises:
        ImportError: Hypothesis is not installed (``pip install cas_async[test]``).
        TypeError: ``cls`` is not a message class.
    """
    _require_hypothesis()
    if not (isinstance(cls, type) and issubclass(cls, Message)) or cls is Message:
        raise TypeError(f"strategy_for needs a message class (a Message subclass), got {cls!r}")
    return _struct(typing.cast(mi.StructType, mi.type_info(cls)), message_fields(cls))


def _require_hypothesis() -> None:
    try:
        import hypothesis  # noqa: F401
    except ImportError as exc:  # pragma: no cover - the test extra installs it
        raise ImportError(
            "cas_async.testing.strategy_for needs Hypothesis: pip install cas_async[test]"
        ) from exc


def _struct(info: mi.StructType, names: tuple[str, ...] | None = None) -> SearchStrategy[Any]:
    from hypothesis import strategies as st

    chosen = {f.name: f for f in info.fields if names is None or f.name in names}
    return st.builds(info.cls, **{name: _strategy(f.type) for name, f in chosen.items()})


def _strategy(node: mi.Type) -> SearchStrategy[Any]:
    from hypothesis import strategies as st

    match node:
        case mi.Metadata(type=inner):
            return _strategy(inner)
        case mi.IntType():
            return _integers(node)
        case mi.FloatType():
            return _floats(node)
        case mi.BoolType():
            return st.booleans()
        case mi.StrType():
            return st.text(max_size=20)
        case mi.BytesType():
            return st.binary(max_size=20)
        case mi.NoneType():
            return st.none()
        case mi.AnyType():
            return _plain()
        case mi.EnumType(cls=kind):
            return st.sampled_from(list(kind))
        case mi.LiteralType(values=values):
            return st.sampled_from(list(values))
        case mi.UnionType(types=options):
            return st.one_of(*(_strategy(option) for option in options))
        case mi.ListType(item_type=item):
            return st.lists(_strategy(item), max_size=_MAX_ITEMS)
        case mi.VarTupleType(item_type=item):
            return st.lists(_strategy(item), max_size=_MAX_ITEMS).map(tuple)
        case mi.TupleType(item_types=items):
            return st.tuples(*(_strategy(item) for item in items))
        case mi.DictType(key_type=mi.AnyType(), value_type=values):  # a bare dict
            keys = st.one_of(st.none(), st.booleans(), st.integers(*_INT64), st.text(max_size=8))
            return st.dictionaries(keys, _strategy(values), max_size=_MAX_ITEMS)
        case mi.DictType(key_type=keys, value_type=values):
            return st.dictionaries(_strategy(keys), _strategy(values), max_size=_MAX_ITEMS)
        case mi.StructType(cls=kind):
            names = message_fields(kind) if issubclass(kind, Message) else None
            return st.deferred(lambda: _struct(node, names))
        case mi.CustomType(cls=kind) if issubclass(kind, np.ndarray):
            return _arrays()
    raise TypeError(f"no strategy for {node!r}")


def _integers(node: mi.IntType) -> SearchStrategy[int]:
    from hypothesis import strategies as st

    low = node.ge if node.ge is not None else None if node.gt is None else node.gt + 1
    high = node.le if node.le is not None else None if node.lt is None else node.lt - 1
    return st.integers(
        _INT64[0] if low is None else max(low, _INT64[0]),
        _INT64[1] if high is None else min(high, _INT64[1]),
    )


def _floats(node: mi.FloatType) -> SearchStrategy[float]:
    from hypothesis import strategies as st

    low = node.ge if node.ge is not None else node.gt
    high = node.le if node.le is not None else node.lt
    bounded = low is not None or high is not None  # msgspec refuses NaN under any bound
    return st.floats(
        min_value=None if low is None else float(low),
        max_value=None if high is None else float(high),
        exclude_min=node.gt is not None,
        exclude_max=node.lt is not None,
        allow_nan=not bounded,
        allow_infinity=not bounded,
    )


def _plain() -> SearchStrategy[Any]:
    """What a bare ``list``, ``tuple`` or ``dict`` field holds: msgpack's plain values."""
    from hypothesis import strategies as st

    scalars = st.one_of(
        st.none(), st.booleans(), st.integers(*_INT64), st.floats(), st.text(max_size=8)
    )

    def containers(inner: SearchStrategy[Any]) -> SearchStrategy[Any]:
        return st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3)

    return st.recursive(scalars, containers, max_leaves=8)


def _arrays() -> SearchStrategy[Any]:
    from hypothesis import strategies as st
    from hypothesis.extra import numpy as hnp

    return hnp.arrays(
        dtype=st.sampled_from([np.float64, np.int64, np.float32, np.uint8]),
        shape=hnp.array_shapes(max_dims=2, max_side=4),
    )
