"""Messages: the framework header and the ``Message`` base, a msgspec Struct with a stable tag.

A user message is a class deriving from :class:`Message` whose fields are declared
with annotations, as for any msgspec Struct::

    class Ping(Message):
        n: int
        note: str = ""

    Ping(3)                      # fields are positional, the header keyword-only
    match msg:
        case Ping(n=n): ...

Every message class gets a *stable tag* when it is defined: a 31-bit CRC of its
wire name, which is its fully qualified name (``examples.gathering.messages.Position``)
unless ``@message(name=...)`` gives another. Tags never depend on the order in
which classes are defined, so two processes that import their modules in a
different order agree on every one; a module run with ``python -m pkg.mod`` names
its classes as when it is imported. Two different wire names with the same CRC
are refused when the second class is defined. A class defined again under the
same name (a module reloaded) takes the name over; two live classes with one
name cannot be messages of one robot's stack (see :mod:`cas_async._wire._codec`).

The header (thesis Fig. 3) is filled by the runtime when the message is sent;
users only choose ``msg_type`` (and only when they want NEGOTIATION or DENY).
On the wire a message is a msgpack array: the tag, the fields in declaration
order, then the header.

Bounds are msgspec's own: ``Annotated[float, msgspec.Meta(ge=0)]``;
:data:`Finite` (and :func:`finite` with bounds) refuses NaN and infinities.
"""

from __future__ import annotations

import enum
import inspect
import reprlib
import sys
import typing
import weakref
import zlib
from collections.abc import Callable
from typing import Annotated, Any, Final, TypeVar, dataclass_transform, overload

import msgspec

from .._errors import MessageDefinitionError
from ._fingerprint import schema_text

__all__ = [
    "HEADER_FIELDS",
    "MAX_TAG",
    "Finite",
    "Message",
    "MsgType",
    "all_messages",
    "finite",
    "message",
    "message_fields",
    "wire_name",
]


class MsgType(enum.IntEnum):
    """What a message expects of its receiver (thesis §3.3)."""

    NEGOTIATION = 0
    """A reply is expected (internal ones are answered by ``get_intra_msg_reply``)."""
    ACCEPT = 1
    """No reply is needed; the receiver simply takes it."""
    DENY = 2
    """A refusal, typically the answer to a NEGOTIATION."""


HEADER_FIELDS: Final = ("msg_type", "msg_id", "robot_id", "src_layer", "dst_layer", "corr_id")
"""Header attributes, in wire order. ``corr_id`` is the ``msg_id`` a reply answers (0: none)."""

MAX_TAG: Final = 2**31 - 1
"""Largest tag: tags are 31-bit CRCs of wire names (or chosen, within ``[0, MAX_TAG]``)."""

_LARGEST: Final = sys.float_info.max


def finite(
    *,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
) -> msgspec.Meta:
    """Bounds on a float that also refuse NaN and both infinities.

    msgspec refuses NaN under any bound; a float with no bound on one side is
    bounded there by the largest finite float, so infinities are refused too::

        speed: Annotated[float, finite(ge=0)]      # finite and not negative
        x: Annotated[float, Finite]                # finite: finite() with no bound

    Raises:
        ValueError: both ``ge`` and ``gt`` (or ``le`` and ``lt``) are given.
    """
    if ge is not None and gt is not None:
        raise ValueError("finite(): give ge or gt, not both")
    if le is not None and lt is not None:
        raise ValueError("finite(): give le or lt, not both")
    limits: dict[str, Any] = (
        {"gt": gt} if gt is not None else {"ge": -_LARGEST if ge is None else ge}
    )
    limits.update({"lt": lt} if lt is not None else {"le": _LARGEST if le is None else le})
    meta: msgspec.Meta = msgspec.Meta(**limits)
    return meta


Finite: Final = finite()
"""``Annotated[float, Finite]``: no NaN, no infinity (checked when a message arrives)."""

_Id = Annotated[int, msgspec.Meta(ge=0)]
"""Message ids, and ``corr_id`` (0: not a reply), are never negative."""

_SHORT: Final = reprlib.Repr()  # field values in log lines: strings and lists capped
_SHORT.maxstring = _SHORT.maxother = 60
_SHORT.maxlist = _SHORT.maxtuple = _SHORT.maxdict = _SHORT.maxset = 6
_SHORT.maxlevel = 2

_names: weakref.WeakKeyDictionary[type, str] = weakref.WeakKeyDictionary()
"""The wire name of every message class (a tag's CRC input)."""
_tags: dict[int, str] = {}
"""Wire name by tag, of every class defined: a CRC collision of two names is refused."""
_namespaces: weakref.WeakKeyDictionary[type, dict[str, Any]] = weakref.WeakKeyDictionary()
"""Each class's namespace as written, so ``@message(name=...)`` can define it again."""
_superseded: weakref.WeakSet[type] = weakref.WeakSet()
"""Classes ``@message(name=...)`` defined again: no longer messages of anyone's stack."""
_latest: weakref.WeakValueDictionary[tuple[str, str], type] = weakref.WeakValueDictionary()
"""The newest class by where it is defined and wire name: one defined again supersedes the old.

A module run with ``python -m`` and imported too is two modules (``__main__`` and its
name): its classes stay two, and a stack of both is refused naming them."""
_defined: list[Any] = [0, ()]
"""How many classes were defined, and :func:`all_messages` as of then."""


def _module_name(module: str) -> str:
    """A module's importable name: a module run as ``python -m pkg.mod`` is ``pkg.mod`` too."""
    if module == "__main__":
        spec = getattr(sys.modules.get("__main__"), "__spec__", None)
        if spec is not None and spec.name:
            return str(spec.name)
    return module


def _tag_of(name: str) -> int:
    return zlib.crc32(name.encode()) & MAX_TAG


class _MessageMeta(msgspec.StructMeta):
    """Gives every message class its tag, and refuses what cannot be a message."""

    def __new__(
        mcls,
        cls_name: str,
        bases: tuple[type, ...],
        namespace: dict[str, Any],
        /,
        *,
        wire_name: str | None = None,
        **options: Any,
    ) -> _MessageMeta:
        if not any(isinstance(base, _MessageMeta) for base in bases):  # Message itself
            return super().__new__(mcls, cls_name, bases, namespace, **options)
        qualname = namespace.get("__qualname__", cls_name)
        for clash in sorted(set(namespace.get("__annotations__", {})) & set(HEADER_FIELDS)):
            raise MessageDefinitionError(f"{qualname}.{clash}: the name is taken by the header")
        module = namespace.get("__module__", "")
        name = wire_name or f"{_module_name(module)}.{qualname}"
        tag = options.pop("tag", None)
        if tag is None:
            tag = _tag_of(name)
        elif type(tag) is not int or not 0 <= tag <= MAX_TAG:
            raise MessageDefinitionError(
                f"{qualname}: a tag is an int in [0, {MAX_TAG}], got {tag!r}"
            )
        known = _tags.get(tag)
        if known is not None and known != name:
            raise MessageDefinitionError(
                f"{qualname}: its wire name {name!r} has the tag {tag} of {known!r}; "
                "give one of them another name with @message(name=...)"
            )
        kept = dict(namespace)  # before type() consumes __classcell__
        try:
            cls = super().__new__(mcls, cls_name, bases, namespace, tag=tag, **options)
        except (TypeError, ValueError) as exc:  # field order, bad options...
            raise MessageDefinitionError(f"{qualname}: {exc}") from exc
        _check_fields(cls)
        _tags[tag] = name
        _defined[0] += 1
        _names[cls] = name
        _namespaces[cls] = kept
        older = _latest.get((f"{module}.{qualname}", name))
        if older is not None:  # the module was run again: the new class takes the name over
            _superseded.add(older)
        _latest[(f"{module}.{qualname}", name)] = cls
        return cls


def _check_fields(cls: Any) -> None:
    """Raises ``MessageDefinitionError`` unless ``cls`` can travel (its schema, computed once)."""
    where = cls.__qualname__
    try:
        typing.get_type_hints(cls, include_extras=True)
    except Exception as exc:
        raise MessageDefinitionError(f"{where}: cannot resolve field annotations: {exc}") from exc
    try:
        schema_text(cls)
    except (TypeError, ValueError) as exc:  # msgspec, or we, name the type that cannot travel
        raise MessageDefinitionError(f"{where}: {exc}") from exc


# kw_only: the header fields are keyword-only, and msgspec places them after the
# subclass's own fields (positional, in declaration order). array_like: on the wire
# a message is an array, its tag first. forbid_unknown_fields: an array longer than
# the class is refused, not silently cut.
class Message(
    msgspec.Struct,
    metaclass=_MessageMeta,
    kw_only=True,
    array_like=True,
    forbid_unknown_fields=True,
    repr_omit_defaults=False,
):
    """Base of every message. The header fields are filled by the runtime on send."""

    msg_type: MsgType = MsgType.ACCEPT
    msg_id: _Id = 0
    robot_id: int = 0
    src_layer: int = 0
    dst_layer: int = 0
    corr_id: _Id = 0

    def __repr__(self) -> str:
        return _text(self, repr)

    def __brief__(self) -> str:
        """The message for a log line, each field capped (:func:`cas_async._core._logs.brief`)."""
        return _text(self, _SHORT.repr)


def _text(msg: Message, show: Callable[[Any], str]) -> str:
    """``Class(field=value, ...) [header]``, each value as ``show`` writes it."""
    names = message_fields(type(msg))
    body = ", ".join(f"{name}={show(getattr(msg, name))}" for name in names)
    kind = getattr(msg.msg_type, "name", msg.msg_type)
    if not msg.msg_id:  # not stamped: the header means nothing yet
        return f"{type(msg).__name__}({body}) [not sent, {kind}]"
    return (
        f"{type(msg).__name__}({body}) "
        f"[#{msg.msg_id} {kind} robot {msg.robot_id} "
        f"L{msg.src_layer}->L{msg.dst_layer}"
        + (f" reply to #{msg.corr_id}]" if msg.corr_id else "]")
    )


M = TypeVar("M", bound=Message)


@overload
def message(cls: type[M], /) -> type[M]: ...
@overload
def message(
    *, name: str | None = None, type_id: int | None = None
) -> Callable[[type[M]], type[M]]: ...
@dataclass_transform()
def message(
    cls: type[M] | None = None, /, *, name: str | None = None, type_id: int | None = None
) -> type[M] | Callable[[type[M]], type[M]]:
    """Optional: gives a message class another wire name (or tag) than its own.

    Every ``Message`` subclass is a message without it. ``@message`` alone checks
    that the class is one; ``@message(name="gathering.Position")`` makes the tag a
    CRC of that name (a name that stays when the class moves to another module),
    ``@message(type_id=7)`` sets the tag itself.

    Raises:
        MessageDefinitionError: not a ``Message`` subclass, a tag out of range, or
            a tag another wire name already has.
    """

    def wrap(klass: type[M]) -> type[M]:
        if not (isinstance(klass, type) and issubclass(klass, Message)) or klass is Message:
            raise MessageDefinitionError(f"@message needs a subclass of Message, got {klass!r}")
        if name is None and type_id is None:
            return klass
        namespace = _namespaces.get(klass)
        if namespace is None:  # pragma: no cover - every subclass is recorded
            raise MessageDefinitionError(f"{klass.__qualname__}: cannot be named again")
        options: dict[str, Any] = {} if type_id is None else {"tag": type_id}
        again = _MessageMeta(
            klass.__name__,
            klass.__bases__,
            dict(namespace),
            wire_name=name or _names.get(klass),
            **options,
        )
        _superseded.add(klass)
        _defined[0] += 1
        return again  # type: ignore[return-value]

    return wrap if cls is None else wrap(cls)


def message_fields(cls: type[Message]) -> tuple[str, ...]:
    """The fields a message class declares (its own and its bases'), without the header."""
    return cls.__struct_fields__[: -len(HEADER_FIELDS)]


def wire_name(cls: type[Message]) -> str:
    """The name ``cls``'s tag is the CRC of: its full name, or the one ``@message`` gave."""
    try:
        return _names[cls]
    except KeyError:
        raise MessageDefinitionError(f"{cls!r} is not a message class") from None


def all_messages() -> tuple[type[Message], ...]:
    """Every message class defined in this process and still in use, by tag.

    What a robot given no ``messages=`` accepts: as before, the classes imported
    so far (import the same message modules in every process).
    """
    count, known = _defined
    if known and known[0] == count:
        return known[1]  # type: ignore[no-any-return]
    found: list[type[Message]] = []
    pending = list(Message.__subclasses__())
    while pending:
        cls = pending.pop()
        pending.extend(cls.__subclasses__())
        if cls in _names and cls not in _superseded and not inspect.isabstract(cls):
            found.append(cls)
    classes = tuple(sorted(found, key=lambda c: (c.__struct_config__.tag, c.__qualname__)))
    _defined[1] = (count, classes)
    return classes
