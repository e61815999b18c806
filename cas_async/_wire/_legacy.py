"""The message API of 0.1.0 that 0.2.0 still gives, with a warning (see ``CHANGELOG.md``).

Before messages became msgspec Structs, bounds were ``Bounds(ge=...)`` and the runtime's
description of a message class was ``spec_of(cls)``, a :class:`MessageSpec`. The
root face hands these out for one more release, each with a ``DeprecationWarning``
naming what replaced it: ``msgspec.Meta`` (or :func:`~cas_async.finite`) for bounds,
:func:`~cas_async.message_fields` and ``msgspec.structs.fields`` for a description.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import msgspec

from ._message import Message, finite, message_fields, wire_name

__all__ = ["Bounds", "MessageSpec", "spec_of"]


def Bounds(
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    finite: bool = False,
) -> msgspec.Meta:
    """0.1.0's bounds on a number: ``msgspec.Meta`` today (``Bounds(ge=0)`` is ``Meta(ge=0)``).

    ``finite=True`` also refuses NaN and both infinities, as :func:`~cas_async.finite`
    does; msgspec refuses NaN under any bound anyway.

    Raises:
        ValueError: the bounds leave no value (msgspec's own check).
    """
    bounds = {"ge": ge, "gt": gt, "le": le, "lt": lt}
    given = {name: value for name, value in bounds.items() if value is not None}
    if finite:
        return _finite(**given)
    meta: Callable[..., msgspec.Meta] = msgspec.Meta  # one overload per pair of bounds
    return meta(**given)


_finite = finite  # the parameter named finite hides the function inside Bounds


@dataclass(frozen=True, slots=True)
class MessageSpec:
    """What 0.1.0's runtime knew of a message class: today read from the class itself.

    Attributes:
        cls: the class.
        name: its wire name (what its tag is the CRC of).
        type_id: its tag (``cls.__struct_config__.tag``).
        field_names: the fields it declares, without the header
            (:func:`~cas_async.message_fields`).
        field_types: their annotations, in the same order (``msgspec.structs.fields``).
    """

    cls: type[Message]
    name: str
    type_id: int
    field_names: tuple[str, ...]
    field_types: tuple[object, ...]


def spec_of(cls: type[Message]) -> MessageSpec:
    """0.1.0's description of a message class, built from the class."""
    names = message_fields(cls)
    types = {field.name: field.type for field in msgspec.structs.fields(cls)}
    tag = cls.__struct_config__.tag
    return MessageSpec(
        cls=cls,
        name=wire_name(cls),
        type_id=tag if isinstance(tag, int) else 0,
        field_names=names,
        field_types=tuple(types[name] for name in names),
    )
