"""Hypothesis strategies of messages, made from their ``@message`` annotations."""

from __future__ import annotations

import enum
import math
import types
import typing
from typing import Annotated, Any

import numpy as np

from .._bounds import Bounds
from .._message import Message, spec_of

if typing.TYPE_CHECKING:
    from hypothesis.strategies import SearchStrategy

__all__ = ["strategy_for"]

_INT64: typing.Final = (-(2**63), 2**63 - 1)
"""The ints every field carries (msgpack's signed 64 bits)."""
_MAX_ITEMS: typing.Final = 6
"""Items per generated list, tuple or dict: enough to find shapes, few enough to stay fast."""


def strategy_for(cls: type[Message]) -> SearchStrategy[Any]:
    """A Hypothesis strategy of ``cls`` messages, every field drawn from its annotation.

    Fields follow their types, bounds included (``Annotated[float, Finite]`` draws
    no NaN, ``Bounds(ge=0)`` nothing below 0; unbounded floats draw NaN and
    infinities too); nested messages, enums, optional fields, lists, tuples, dicts
    and numpy arrays are drawn in kind. Headers are left unset. For example::

        @given(strategy_for(Meet))
        def test_meet_survives_the_codec(meet: Meet) -> None:
            assert_roundtrip(meet, messages=MESSAGES)

    Raises:
        ImportError: Hypothesis is not installed (``pip install cas_async[test]``).
        TypeError: ``cls`` is not a ``@message`` class.
    """
    _require_hypothesis()
    from hypothesis import strategies as st

    spec = spec_of(cls)
    hints = typing.get_type_hints(cls, include_extras=True)
    fields = {name: _strategy(hints[name], f"{cls.__name__}.{name}") for name in spec.field_names}
    return st.builds(cls, **fields)


def _require_hypothesis() -> None:
    try:
        import hypothesis  # noqa: F401
    except ImportError as exc:  # pragma: no cover - the test extra installs it
        raise ImportError(
            "cas_async.testing.strategy_for needs Hypothesis: pip install cas_async[test]"
        ) from exc


def _strategy(annotation: Any, where: str) -> SearchStrategy[Any]:
    from hypothesis import strategies as st

    simple = {
        int: st.integers(*_INT64),
        float: st.floats(),
        bool: st.booleans(),
        str: st.text(max_size=20),
        bytes: st.binary(max_size=20),
        type(None): st.none(),
        None: st.none(),
    }
    if annotation in simple:
        return simple[annotation]
    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if origin is Annotated:
        base, *extras = args
        bounds = [extra for extra in extras if isinstance(extra, Bounds)]
        return _bounded(base, bounds, where) if bounds else _strategy(base, where)
    if annotation in (list, tuple, dict):
        plain = _plain()
        if annotation is dict:
            return st.dictionaries(st.text(max_size=8), plain, max_size=_MAX_ITEMS)
        items = st.lists(plain, max_size=_MAX_ITEMS)
        return items if annotation is list else items.map(tuple)
    if annotation is np.ndarray or origin is np.ndarray:
        return _arrays()
    if isinstance(annotation, type):
        if issubclass(annotation, enum.IntEnum):
            return st.sampled_from(list(annotation))
        if issubclass(annotation, Message):
            return strategy_for(annotation)
    if origin in (typing.Union, types.UnionType):
        return st.one_of(*(_strategy(option, where) for option in args))
    if origin is list and len(args) == 1:
        return st.lists(_strategy(args[0], where), max_size=_MAX_ITEMS)
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
        return st.lists(_strategy(args[0], where), max_size=_MAX_ITEMS).map(tuple)
    if origin is tuple and args:
        return st.tuples(*(_strategy(arg, where) for arg in args))
    if origin is dict and len(args) == 2:
        keys, values = (_strategy(arg, where) for arg in args)
        return st.dictionaries(keys, values, max_size=_MAX_ITEMS)
    raise TypeError(f"{where}: no strategy for {annotation!r}")


def _bounded(base: Any, bounds: list[Bounds], where: str) -> SearchStrategy[Any]:
    from hypothesis import strategies as st

    low = max((b for bound in bounds for b in (bound.ge, bound.gt) if b is not None), default=None)
    high = min((b for bound in bounds for b in (bound.le, bound.lt) if b is not None), default=None)
    exclude_low = any(bound.gt is not None and bound.gt == low for bound in bounds)
    exclude_high = any(bound.lt is not None and bound.lt == high for bound in bounds)
    if base is int:
        lowest = _INT64[0] if low is None else math.ceil(low)
        if exclude_low and lowest == low:
            lowest += 1
        highest = _INT64[1] if high is None else math.floor(high)
        if exclude_high and highest == high:
            highest -= 1
        return st.integers(max(lowest, _INT64[0]), min(highest, _INT64[1]))
    if base is not float:
        raise TypeError(f"{where}: bounds on {base!r}")
    finite = any(bound.finite for bound in bounds) or low is not None or high is not None
    return st.floats(
        min_value=low,
        max_value=high,
        exclude_min=exclude_low,
        exclude_max=exclude_high,
        allow_nan=not finite,
        allow_infinity=not finite,
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
