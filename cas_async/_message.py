"""Messages: the framework header, the ``Message`` base and the ``@message`` registry.

A user message is a class deriving from :class:`Message`, decorated with
:func:`message`, whose fields are declared with annotations::

    @message
    class Ping(Message):
        n: int
        note: str = ""

The decorator turns the class into a slotted dataclass and registers it under a
*stable* type id, derived from its name (or given explicitly), never from the
order of registration: two processes that import their modules in a different
order still agree on every id.

The header (thesis Fig. 3) is filled by the runtime when the message is sent;
users only choose ``msg_type`` (and only when they want NEGOTIATION or DENY).
"""

from __future__ import annotations

import dataclasses
import enum
import inspect
import reprlib
import typing
import zlib
from collections.abc import Callable, Iterable, Iterator
from typing import Any, Final, TypeVar, dataclass_transform, overload

from ._errors import DecodeError, MessageDefinitionError
from ._schema import FieldType, NestedMessages, field_type

__all__ = [
    "HEADER_FIELDS",
    "Message",
    "MessageSpec",
    "MsgType",
    "message",
    "nested_to_wire",
    "registered",
    "registry_generation",
    "spec_of",
    "specs_for",
]


class MsgType(enum.IntEnum):
    """What a message expects of its receiver (thesis §3.3)."""

    NEGOTIATION = 0
    """A reply is expected (internal ones are answered by ``get_intra_msg_reply``)."""
    ACCEPT = 1
    """No reply is needed; the receiver simply takes it."""
    DENY = 2
    """A refusal, typically the answer to a NEGOTIATION."""


HEADER_FIELDS: Final = ("msg_id", "msg_type", "robot_id", "src_layer", "dst_layer", "corr_id")
"""Header attributes, in wire order. ``corr_id`` is the ``msg_id`` a reply answers (0: none)."""

_MAX_TYPE_ID: Final = 2**31 - 1

_SHORT: Final = reprlib.Repr()  # field values in log lines: strings and lists capped
_SHORT.maxstring = _SHORT.maxother = 60
_SHORT.maxlist = _SHORT.maxtuple = _SHORT.maxdict = _SHORT.maxset = 6
_SHORT.maxlevel = 2


@dataclasses.dataclass(slots=True, kw_only=True, repr=False)
class Message:
    """Base of every message. The header fields are filled by the runtime on send."""

    msg_type: MsgType = MsgType.ACCEPT
    msg_id: int = 0
    robot_id: int = 0
    src_layer: int = 0
    dst_layer: int = 0
    corr_id: int = 0

    def __init_subclass__(cls, **kwargs: Any) -> None:
        # Zero-argument super() fails here: slots=True remade this class after the
        # method was compiled against the first one.
        super(Message, cls).__init_subclass__(**kwargs)
        # Until @message makes the class a dataclass, constructing one says what is
        # missing (instead of Message.__init__ refusing the first field by name).
        if "__init__" not in cls.__dict__:
            cls.__init__ = _undecorated_init  # type: ignore[method-assign]

    def __repr__(self) -> str:
        return _text(self, repr)

    def __brief__(self) -> str:
        """The message for a log line: each field capped (see :func:`cas_async._logs.brief`)."""
        return _text(self, _SHORT.repr)


def _text(msg: Message, show: Callable[[Any], str]) -> str:
    """``Class(field=value, ...) [header]``, each value as ``show`` writes it."""
    spec = _by_class.get(type(msg))
    names = spec.field_names if spec is not None else ()
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


def _undecorated_init(self: Message, *args: Any, **kwargs: Any) -> None:
    cls = type(self)
    raise MessageDefinitionError(
        f"{cls.__module__}.{cls.__qualname__} is a Message subclass without @message: "
        "decorate the class with @message (from cas_async import message) so that its "
        "annotated fields become the message's fields"
    )


M = TypeVar("M", bound=Message)


@dataclasses.dataclass(frozen=True, slots=True)
class MessageSpec:
    """What the runtime knows of a registered message class."""

    cls: type[Message]
    name: str
    type_id: int
    field_names: tuple[str, ...]
    field_types: tuple[FieldType, ...]

    @property
    def schema(self) -> str:
        """Canonical text of the wire schema, used by the stack fingerprint."""
        fields = ",".join(
            f"{n}:{t.text}" for n, t in zip(self.field_names, self.field_types, strict=True)
        )
        return f"{self.type_id}:{self.name}({fields})"


_by_id: dict[int, MessageSpec] = {}
_by_class: dict[type[Message], MessageSpec] = {}
_by_name: dict[str, MessageSpec] = {}
_generation = 0  # counts the changes to the registry


def _type_id_for(name: str) -> int:
    return zlib.crc32(name.encode()) & _MAX_TYPE_ID


def _same_class(a: type, b: type) -> bool:
    """True when ``b`` is ``a`` defined again (module re-imported, ``__main__`` run twice)."""
    return (a.__module__, a.__qualname__) == (b.__module__, b.__qualname__)


def _register(cls: type[Message], name: str | None, type_id: int | None) -> MessageSpec:
    """Registers a class that ``message()`` has checked and made a dataclass."""
    name = name or cls.__name__
    tid = _type_id_for(name) if type_id is None else type_id
    if type(tid) is not int or not 0 <= tid <= _MAX_TYPE_ID:
        raise MessageDefinitionError(f"{name}: type_id must be an int in [0, {_MAX_TYPE_ID}]")
    try:
        hints = typing.get_type_hints(cls, include_extras=True)  # keeps Annotated bounds
    except Exception as exc:
        raise MessageDefinitionError(f"{name}: cannot resolve field annotations: {exc}") from exc
    fields = [f for f in dataclasses.fields(cls) if f.name not in HEADER_FIELDS]
    types_ = tuple(field_type(hints[f.name], f"{name}.{f.name}", _NESTED) for f in fields)
    spec = MessageSpec(cls, name, tid, tuple(f.name for f in fields), types_)
    found = [e for e in (_by_name.get(name), _by_id.get(tid)) if e is not None]
    for existing in found:  # check both before dropping anything: a refusal changes nothing
        if not _same_class(existing.cls, cls):
            raise MessageDefinitionError(
                f"cannot register {cls.__module__}.{cls.__qualname__} as {name!r} (id {tid}): "
                f"{existing.cls.__module__}.{existing.cls.__qualname__} is registered as "
                f"{existing.name!r} (id {existing.type_id}); pass @message(name=...) or type_id=..."
            )
    for existing in found:
        _unregister(existing)
    global _generation
    _generation += 1
    _by_id[tid] = _by_class[cls] = _by_name[name] = spec
    return spec


def _unregister(spec: MessageSpec) -> None:
    _by_id.pop(spec.type_id, None)
    _by_class.pop(spec.cls, None)
    _by_name.pop(spec.name, None)


@overload
def message(cls: type[M], /) -> type[M]: ...
@overload
def message(
    *, name: str | None = None, type_id: int | None = None
) -> Callable[[type[M]], type[M]]: ...
@dataclass_transform()  # type checkers then see each message's generated __init__
def message(
    cls: type[M] | None = None, /, *, name: str | None = None, type_id: int | None = None
) -> type[M] | Callable[[type[M]], type[M]]:
    """Makes a ``Message`` subclass a slotted dataclass and registers it.

    Args:
        cls: the class (when used as a bare ``@message``).
        name: wire name; defaults to the class name. Must be unique in the process.
        type_id: explicit wire id in ``[0, 2**31)``; defaults to a hash of ``name``.

    Raises:
        MessageDefinitionError: unsupported field type, header name clash, or a name
            or id already used by another class.
    """

    def wrap(klass: type[M]) -> type[M]:
        if not (isinstance(klass, type) and issubclass(klass, Message)) or klass is Message:
            raise MessageDefinitionError(f"@message needs a subclass of Message, got {klass!r}")
        where = name or klass.__name__
        # Before dataclass(): a header name redeclared with a default makes it fail first.
        for clash in sorted(set(inspect.get_annotations(klass)) & set(HEADER_FIELDS)):
            raise MessageDefinitionError(f"{where}.{clash}: the name is taken by the header")
        if klass.__dict__.get("__init__") is _undecorated_init:
            del klass.__init__  # dataclass() writes the real one only where none is
        try:
            made = dataclasses.dataclass(slots=True, repr=False)(klass)
        except (TypeError, ValueError) as exc:  # field order, @message applied twice...
            raise MessageDefinitionError(f"{where}: {exc}") from exc
        _register(made, name, type_id)
        return made

    return wrap if cls is None else wrap(cls)


def spec_of(cls: type[Message]) -> MessageSpec:
    """The spec of a registered class; a clear error when ``@message`` was forgotten."""
    spec = _by_class.get(cls)
    if spec is None:
        raise MessageDefinitionError(
            f"{cls.__qualname__} is not a registered message: decorate it with @message"
        )
    return spec


def registered() -> Iterator[MessageSpec]:
    """Every registered message spec, in type-id order."""
    return iter(sorted(_by_id.values(), key=lambda s: s.type_id))


def registry_generation() -> int:
    """A number that changes whenever a message class is registered (or replaced)."""
    return _generation


def specs_for(classes: Iterable[type[Message]] | None) -> dict[int, MessageSpec]:
    """The specs a robot accepts: the given classes, or every registered one."""
    if classes is None:
        return dict(_by_id)
    return {spec.type_id: spec for spec in map(spec_of, classes)}


def _decode_nested(value: Any, path: str, expected: type) -> Message:
    """Decodes a nested message sent as ``[type_id, *fields]`` (no header)."""
    if type(value) is not tuple or not value or type(value[0]) is not int:
        raise DecodeError(
            f"{path}: expected {expected.__name__} [type_id, fields...]", "wrong_type"
        )
    spec = _by_id.get(value[0])
    if spec is None or not issubclass(spec.cls, expected):
        raise DecodeError(f"{path}: type id {value[0]} is not a {expected.__name__}", "wrong_type")
    if len(value) != 1 + len(spec.field_names):
        raise DecodeError(
            f"{path}: {spec.name} has {len(spec.field_names)} fields, got {len(value) - 1}",
            "wrong_arity",
        )
    obj = object.__new__(spec.cls)
    for attr, kind, raw in zip(spec.field_names, spec.field_types, value[1:], strict=True):
        setattr(obj, attr, kind.convert(raw, f"{path}.{attr}"))
    for attr in HEADER_FIELDS:
        setattr(obj, attr, 0)
    obj.msg_type = MsgType.ACCEPT
    return obj


def nested_to_wire(obj: Message) -> tuple[Any, ...]:
    """Encodes a message nested in a field as ``(type_id, *fields)``."""
    spec = spec_of(type(obj))
    return (spec.type_id, *(getattr(obj, name) for name in spec.field_names))


_NESTED: Final = NestedMessages(Message, _decode_nested)
"""How the schema recognises and decodes fields that hold messages."""
