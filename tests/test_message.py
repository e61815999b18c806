"""@message: registration, stable type ids, definition errors, defaults and repr."""

from __future__ import annotations

import dataclasses
import enum
import typing
import zlib
from typing import Any

import pytest

from cas_async import Message, MessageDefinitionError, MessageSpec, MsgType, message, spec_of
from cas_async._message import HEADER_FIELDS, registered, specs_for


@message
class MsgPing(Message):
    n: int
    note: str = ""


@message(name="msg-test.renamed")
class MsgRenamed(Message):
    value: float


@message(type_id=1_234_567_891)
class MsgFixedId(Message):
    flag: bool = False


@message
class MsgWithFactory(Message):
    items: list[int] = dataclasses.field(default_factory=list)


@message
class MsgPingPlus(MsgPing):
    extra: bytes = b""


class MsgNotDecorated(Message):
    n: int = 0


def by_type_id(type_id: int) -> MessageSpec | None:
    """The spec registered under a wire type id, if any."""
    return next((spec for spec in registered() if spec.type_id == type_id), None)


def crc_id(name: str) -> int:
    return zlib.crc32(name.encode()) & 0x7FFF_FFFF


# --- registration and type ids ----------------------------------------------------------


@pytest.mark.parametrize(
    ("cls", "name", "type_id"),
    [
        pytest.param(MsgPing, "MsgPing", crc_id("MsgPing"), id="from-class-name"),
        pytest.param(
            MsgRenamed, "msg-test.renamed", crc_id("msg-test.renamed"), id="explicit-name"
        ),
        pytest.param(MsgFixedId, "MsgFixedId", 1_234_567_891, id="explicit-type-id"),
        pytest.param(MsgPingPlus, "MsgPingPlus", crc_id("MsgPingPlus"), id="subclass"),
    ],
)
def test_type_id_is_stable_and_registered(cls: type[Message], name: str, type_id: int) -> None:
    spec = spec_of(cls)
    assert (spec.cls, spec.name, spec.type_id) == (cls, name, type_id)
    assert by_type_id(type_id) is spec
    assert spec in list(registered())
    assert specs_for([cls]) == {type_id: spec}


def test_type_id_does_not_depend_on_registration_order() -> None:
    # The id is a pure function of the name: another process computing it agrees.
    assert spec_of(MsgPing).type_id == zlib.crc32(b"MsgPing") & (2**31 - 1)


def test_field_names_exclude_the_header_and_follow_declaration_order() -> None:
    assert spec_of(MsgPing).field_names == ("n", "note")
    assert spec_of(MsgPingPlus).field_names == ("n", "note", "extra")
    assert spec_of(MsgPing).schema == f"{crc_id('MsgPing')}:MsgPing(n:int,note:str)"


def test_registered_is_sorted_by_type_id_and_specs_for_none_is_everything() -> None:
    ids = [spec.type_id for spec in registered()]
    assert ids == sorted(ids)
    everything = specs_for(None)
    assert spec_of(MsgPing) in everything.values()
    assert set(everything) == set(ids)


def test_same_name_from_another_class_is_refused_naming_both() -> None:
    with pytest.raises(MessageDefinitionError) as caught:

        @message(name="MsgPing")
        class Impostor(Message):
            n: int

    text = str(caught.value)
    assert "tests.test_message.MsgPing" in text
    assert "Impostor" in text
    assert spec_of(MsgPing).cls is MsgPing  # the original stays registered


def test_same_type_id_from_another_class_is_refused_naming_both() -> None:
    with pytest.raises(MessageDefinitionError) as caught:

        @message(type_id=1_234_567_891)
        class MsgIdThief(Message):
            n: int

    text = str(caught.value)
    assert "MsgFixedId" in text
    assert "MsgIdThief" in text
    assert by_type_id(1_234_567_891) is spec_of(MsgFixedId)


def test_refused_redefinition_leaves_the_registry_unchanged() -> None:
    # Same module and qualname as an existing registration (so "a redefinition"), but
    # its explicit type id belongs to another class: refused, and the old one stays.
    def define(type_id: int | None) -> type[Message]:
        @message(type_id=type_id)
        class MsgRedefinedBadly(Message):
            n: int

        return MsgRedefinedBadly

    first = define(None)
    with pytest.raises(MessageDefinitionError, match="MsgFixedId"):
        define(1_234_567_891)
    assert spec_of(first).cls is first
    assert by_type_id(crc_id("MsgRedefinedBadly")) is spec_of(first)


def test_redefinition_of_the_same_module_and_qualname_is_allowed() -> None:
    def define() -> type[Message]:
        # Same module and qualname each time, as when a module is imported again.
        @message
        class MsgRedefined(Message):
            n: int

        return MsgRedefined

    first = define()
    second = define()
    assert first is not second
    spec = spec_of(second)
    assert spec.cls is second
    assert by_type_id(crc_id("MsgRedefined")) is spec
    assert [s.name for s in registered()].count("MsgRedefined") == 1


@pytest.mark.parametrize("header", HEADER_FIELDS)
@pytest.mark.parametrize("with_default", [False, True], ids=["no-default", "with-default"])
def test_header_name_clash_is_refused(header: str, with_default: bool) -> None:
    namespace: dict[str, Any] = {"__annotations__": {"payload": int, header: int}}
    if with_default:
        namespace[header] = 7
    cls = type("MsgClash", (Message,), namespace)
    with pytest.raises(MessageDefinitionError, match=rf"MsgClash\.{header}: .*header"):
        message(cls)


@pytest.mark.parametrize(
    ("annotation", "shown"),
    [
        pytest.param(set[int], "set", id="set"),
        pytest.param(frozenset[int], "frozenset", id="frozenset"),
        pytest.param(object, "object", id="object"),
        pytest.param(complex, "complex", id="complex"),
        pytest.param(typing.Any, "Any", id="any"),
        pytest.param(enum.Enum, "Enum", id="plain-enum"),
        pytest.param(dict[int], "dict", id="dict-one-arg"),
        pytest.param(list[int, str], "list", id="list-two-args"),  # type: ignore[misc]
        pytest.param(list[set[int]], "set", id="nested-unsupported"),
        pytest.param("tuple[()]", "tuple", id="empty-tuple"),
    ],
)
def test_unsupported_annotation_is_refused_with_the_field_named(
    annotation: Any, shown: str
) -> None:
    cls = type("MsgUnsupported", (Message,), {"__annotations__": {"ok": int, "bad": annotation}})
    with pytest.raises(MessageDefinitionError, match=r"MsgUnsupported\.bad: unsupported") as caught:
        message(cls)
    assert shown in str(caught.value)


def test_unresolvable_annotation_is_refused() -> None:
    cls = type("MsgForward", (Message,), {"__annotations__": {"later": "NoSuchType"}})
    with pytest.raises(MessageDefinitionError, match="MsgForward: cannot resolve"):
        message(cls)


@pytest.mark.parametrize(
    "target",
    [
        pytest.param(type("PlainClass", (), {}), id="plain-class"),
        pytest.param(Message, id="message-base-itself"),
        pytest.param(3, id="not-a-class"),
        pytest.param(MsgType, id="enum-class"),
    ],
)
def test_non_message_class_is_refused(target: Any) -> None:
    with pytest.raises(MessageDefinitionError, match="needs a subclass of Message"):
        message(target)


@pytest.mark.parametrize(
    "type_id",
    [
        pytest.param(-1, id="negative"),
        pytest.param(2**31, id="too-big"),
        pytest.param(True, id="bool"),
        pytest.param("5", id="str"),
    ],
)
def test_bad_explicit_type_id_is_refused(type_id: Any) -> None:
    cls = type("MsgBadId", (Message,), {"__annotations__": {"n": int}})
    with pytest.raises(MessageDefinitionError, match="type_id must be an int"):
        message(type_id=type_id)(cls)


def test_dataclass_errors_become_definition_errors() -> None:
    with pytest.raises(MessageDefinitionError, match="non-default argument"):

        @message
        class MsgBadOrder(Message):
            a: int = 0
            b: int  # type: ignore[misc]

    with pytest.raises(MessageDefinitionError, match="MsgTwice"):

        @message
        @message
        class MsgTwice(Message):
            n: int = 0


def test_spec_of_an_unregistered_class_explains_what_is_missing() -> None:
    with pytest.raises(MessageDefinitionError, match=r"MsgNotDecorated .*@message"):
        spec_of(MsgNotDecorated)
    with pytest.raises(MessageDefinitionError, match="MsgNotDecorated"):
        specs_for([MsgPing, MsgNotDecorated])


# --- instances: defaults, dataclass behaviour, repr ----------------------------------------


def test_defaults_of_fields_and_header() -> None:
    ping = MsgPing(3)
    assert (ping.n, ping.note) == (3, "")
    assert ping.msg_type is MsgType.ACCEPT
    assert [getattr(ping, name) for name in HEADER_FIELDS if name != "msg_type"] == [0] * 5
    assert MsgWithFactory().items == []
    assert MsgWithFactory().items is not MsgWithFactory().items
    assert MsgPingPlus(1) == MsgPingPlus(n=1, note="", extra=b"")


def test_header_is_keyword_only_and_instances_are_slotted() -> None:
    ping = MsgPing(1, "x", msg_id=9, msg_type=MsgType.DENY, robot_id=4, corr_id=2)
    assert (ping.msg_id, ping.msg_type, ping.robot_id, ping.corr_id) == (9, MsgType.DENY, 4, 2)
    with pytest.raises(TypeError):
        MsgPing(1, "x", 9)  # type: ignore[misc]
    assert not hasattr(ping, "__dict__")
    with pytest.raises(AttributeError):
        ping.typo = 1  # type: ignore[attr-defined]


def test_equality_includes_the_header() -> None:
    assert MsgPing(1) == MsgPing(1)
    assert MsgPing(1) != MsgPing(2)
    assert MsgPing(1) != MsgPing(1, msg_id=1)


@pytest.mark.parametrize(
    ("msg", "expected"),
    [
        pytest.param(MsgPing(1), "MsgPing(n=1, note='') [not sent, ACCEPT]", id="default"),
        pytest.param(
            MsgPing(2, "hi", msg_id=7, robot_id=3, src_layer=1, dst_layer=2),
            "MsgPing(n=2, note='hi') [#7 ACCEPT robot 3 L1->L2]",
            id="header",
        ),
        pytest.param(
            MsgPing(2, msg_id=8, msg_type=MsgType.DENY, corr_id=7),
            "MsgPing(n=2, note='') [#8 DENY robot 0 L0->L0 reply to #7]",
            id="reply",
        ),
        pytest.param(
            MsgRenamed(0.5, msg_type=MsgType.NEGOTIATION),
            "MsgRenamed(value=0.5) [not sent, NEGOTIATION]",
            id="negotiation",
        ),
        pytest.param(
            MsgPing(1, msg_type=2),  # type: ignore[arg-type]
            "MsgPing(n=1, note='') [not sent, 2]",
            id="plain-int-msg-type",
        ),
    ],
)
def test_repr(msg: Message, expected: str) -> None:
    assert repr(msg) == expected


@pytest.mark.parametrize(
    "make",
    [
        pytest.param(lambda: MsgNotDecorated(), id="no-arguments"),
        pytest.param(lambda: MsgNotDecorated(n=1), id="a-field"),  # type: ignore[call-arg]
        pytest.param(lambda: MsgNotDecorated(3), id="positional"),  # type: ignore[call-arg]
    ],
)
def test_constructing_a_message_class_without_at_message_says_what_to_do(make) -> None:
    with pytest.raises(
        MessageDefinitionError,
        match=r"MsgNotDecorated is a Message subclass "
        r"without @message: decorate the class with @message",
    ):
        make()


def test_a_subclass_of_a_message_needs_at_message_too() -> None:
    class MsgPingSubclass(MsgPing):
        pass

    with pytest.raises(
        MessageDefinitionError, match="MsgPingSubclass is a Message subclass without @message"
    ):
        MsgPingSubclass(1)
    assert message(MsgPingSubclass)(1).n == 1  # decorated, it is a message (a new class)


@pytest.mark.parametrize(
    ("member", "value"),
    [
        pytest.param(MsgType.NEGOTIATION, 0, id="negotiation"),
        pytest.param(MsgType.ACCEPT, 1, id="accept"),
        pytest.param(MsgType.DENY, 2, id="deny"),
    ],
)
def test_msg_type_values_are_wire_stable(member: MsgType, value: int) -> None:
    assert isinstance(member, int)
    assert member == value
    assert MsgType(value) is member


def test_msg_type_has_exactly_three_members_and_header_order_is_fixed() -> None:
    assert len(MsgType) == 3
    assert HEADER_FIELDS == ("msg_id", "msg_type", "robot_id", "src_layer", "dst_layer", "corr_id")
