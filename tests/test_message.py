"""Message classes: stable tags, wire names, definition errors, the header, equality and repr."""

from __future__ import annotations

import enum
import functools
import gc
import json
import subprocess
import sys
import textwrap
import zlib
from pathlib import Path
from typing import Annotated, Any

import msgspec
import pytest

from cas_async import Finite, Message, MessageDefinitionError, MsgType, message
from cas_async._wire._message import HEADER_FIELDS, MAX_TAG, all_messages, message_fields, wire_name
from cas_async.transport import Codec
from tests.wire import tag_of

ROOT = Path(__file__).resolve().parents[1]


class MsgPing(Message):
    n: int
    note: str = ""


class MsgPingPlus(MsgPing):
    extra: bytes = b""


@message(name="msg-test.renamed")
class MsgRenamed(Message):
    value: float


@message(type_id=1_234_567_891)
class MsgFixedId(Message):
    flag: bool = False


@message
class MsgDecorated(Message):
    items: list[int] = msgspec.field(default_factory=list)


def crc(name: str) -> int:
    return zlib.crc32(name.encode()) & MAX_TAG


def python(code: str, *args: str, cwd: Path = ROOT) -> Any:
    """Runs ``code`` in a fresh interpreter (a real subprocess); returns what it prints, as JSON."""
    argv = [sys.executable, *(("-c", code) if code else ()), *args]
    done = subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


# --- tags and wire names ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("cls", "name", "tag"),
    [
        pytest.param(MsgPing, f"{__name__}.MsgPing", crc(f"{__name__}.MsgPing"), id="full-name"),
        pytest.param(
            MsgPingPlus, f"{__name__}.MsgPingPlus", crc(f"{__name__}.MsgPingPlus"), id="subclass"
        ),
        pytest.param(MsgRenamed, "msg-test.renamed", crc("msg-test.renamed"), id="renamed"),
        pytest.param(MsgFixedId, f"{__name__}.MsgFixedId", 1_234_567_891, id="chosen-tag"),
        pytest.param(
            MsgDecorated, f"{__name__}.MsgDecorated", crc(f"{__name__}.MsgDecorated"), id="bare-@"
        ),
    ],
)
def test_the_tag_is_the_crc_of_the_wire_name(cls: type[Message], name: str, tag: int) -> None:
    assert (wire_name(cls), tag_of(cls)) == (name, tag)
    assert cls in all_messages()


def test_tags_are_the_same_in_another_process_that_defines_classes_in_another_order(
    tmp_path: Path,
) -> None:
    # This module imported alone: none of the classes pytest defined before it exist there.
    ours = {c.__name__: tag_of(c) for c in (MsgPing, MsgPingPlus, MsgRenamed, MsgFixedId)}
    theirs = python(
        f"import json, {__name__} as m\n"
        f"print(json.dumps({{n: getattr(m, n).__struct_config__.tag for n in {sorted(ours)}}}))"
    )
    assert theirs == ours
    # One module name, its classes written in two orders, each in its own process.
    body = {"A": "class A(Message):\n    x: int\n", "B": "class B(Message):\n    y: str\n"}
    tags = []
    for order in (["A", "B"], ["B", "A"]):
        where = tmp_path / "".join(order)
        where.mkdir()
        source = "from cas_async import Message\n" + "".join(body[n] for n in order)
        (where / "ordered_messages.py").write_text(source)
        code = "import json, ordered_messages as m\nprint(json.dumps({n: getattr(m, n)"
        tags.append(python(code + ".__struct_config__.tag for n in 'AB'}))", cwd=where))
    assert tags[0] == tags[1] == {n: crc(f"ordered_messages.{n}") for n in "AB"}


def test_a_module_run_with_python_m_names_its_classes_as_when_imported(tmp_path: Path) -> None:
    package = tmp_path / "wirepkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "msgs.py").write_text(
        textwrap.dedent(
            """
            import json
            from cas_async import Message
            from cas_async._wire._message import wire_name

            class Ping(Message):
                n: int

            if __name__ == "__main__":
                found = [wire_name(Ping), Ping.__struct_config__.tag]
                import wirepkg.msgs  # the same module once more: two classes of one name
                from cas_async import MessageDefinitionError
                from cas_async.transport import Codec
                try:
                    Codec.for_stack(1)
                except MessageDefinitionError as exc:
                    found.append(str(exc))
                print(json.dumps(found))
            """
        )
    )
    name, tag, refused = python("", "-m", "wirepkg.msgs", cwd=tmp_path)
    imported = python(
        "import json; from wirepkg.msgs import Ping\n"
        "from cas_async._wire._message import wire_name\n"
        "print(json.dumps([wire_name(Ping), Ping.__struct_config__.tag]))",
        cwd=tmp_path,
    )
    assert [name, tag] == imported == ["wirepkg.msgs.Ping", crc("wirepkg.msgs.Ping")]
    assert "have one tag" in refused
    assert "__main__.Ping" in refused
    assert "wirepkg.msgs.Ping and" in refused or "and wirepkg.msgs.Ping" in refused


@functools.cache
def colliding_names() -> tuple[str, str]:
    """Two different wire names with one tag, found by a birthday search (about 90,000 names)."""
    seen: dict[int, str] = {}
    for i in range(1 << 21):
        name = f"msg-test.collide.{i * 0x9E3779B97F4A7C15 % 2**64:016x}"
        other = seen.setdefault(crc(name), name)
        if other != name:
            return other, name
    raise AssertionError("no collision among 2**21 names")  # pragma: no cover


def test_a_crc_collision_of_two_wire_names_is_refused_when_the_second_is_defined() -> None:
    first_name, second_name = colliding_names()
    assert first_name != second_name
    assert crc(first_name) == crc(second_name)

    @message(name=first_name)
    class MsgFirst(Message):
        n: int

    with pytest.raises(MessageDefinitionError) as caught:

        @message(name=second_name)
        class MsgSecond(Message):
            n: int

    text = str(caught.value)
    assert all(part in text for part in ("MsgSecond", first_name, second_name, "@message(name="))
    assert wire_name(MsgFirst) == first_name  # the first keeps its tag


def test_a_chosen_tag_already_taken_is_refused_naming_its_owner() -> None:
    with pytest.raises(MessageDefinitionError, match=rf"MsgThief: .*{__name__}\.MsgFixedId"):

        @message(type_id=1_234_567_891)
        class MsgThief(Message):
            n: int


def test_renaming_makes_a_new_class_and_retires_the_old_one() -> None:
    class MsgBefore(Message):
        n: int

    after = message(name="msg-test.after")(MsgBefore)
    assert after is not MsgBefore
    assert (after.__name__, message_fields(after), wire_name(after)) == (
        "MsgBefore",
        ("n",),
        "msg-test.after",
    )
    assert tag_of(after) == crc("msg-test.after")
    assert after in all_messages()
    assert MsgBefore not in all_messages()
    assert MsgBefore not in Codec.for_stack(1).message_classes  # messages=None: all_messages()


def test_a_class_defined_again_under_its_name_takes_it_over() -> None:
    def define() -> type[Message]:
        class MsgAgain(Message):  # same module and qualname each time, as a reloaded module
            n: int

        return MsgAgain

    first, second = define(), define()
    assert tag_of(first) == tag_of(second)
    assert second in all_messages()
    assert first not in all_messages()
    assert second in Codec.for_stack(1).message_classes
    with pytest.raises(MessageDefinitionError) as caught:  # both, in one stack: refused
        Codec.for_stack(1, [first, second])
    assert str(caught.value).count(f"{__name__}.{first.__qualname__}") >= 2


def test_two_classes_of_one_wire_name_cannot_be_messages_of_one_stack() -> None:
    # Two modules name a class alike: a stack with both is refused naming both. Run
    # elsewhere, so that this process's all_messages() keeps one class per tag.
    error = python(
        textwrap.dedent(
            """
            import json
            from cas_async import Message, MessageDefinitionError, message
            from cas_async.transport import Codec

            @message(name="app.Twin")
            class Left(Message):
                n: int

            @message(name="app.Twin")
            class Right(Message):
                s: str

            errors = []
            for messages in ([Left, Right], None):
                try:
                    Codec.for_stack(2, messages)
                except MessageDefinitionError as exc:
                    errors.append(str(exc))
            print(json.dumps(errors))
            """
        )
    )
    assert len(error) == 2
    for text in error:
        assert all(name in text for name in ("__main__.Left", "__main__.Right", "app.Twin"))


@pytest.mark.parametrize(
    "tag",
    [
        pytest.param(-1, id="negative"),
        pytest.param(MAX_TAG + 1, id="above-31-bits"),
        pytest.param(True, id="bool"),
        pytest.param("5", id="str"),
        pytest.param(5.0, id="float"),
    ],
)
def test_a_bad_chosen_tag_is_refused(tag: Any) -> None:
    cls = type("MsgBadTag", (Message,), {"__annotations__": {"n": int}})
    refused = rf"MsgBadTag: a tag is an int in \[0, {MAX_TAG}\], got {tag!r}"
    with pytest.raises(MessageDefinitionError, match=refused):
        message(type_id=tag)(cls)


def test_a_refused_class_is_no_message_of_any_stack() -> None:
    gc.disable()  # the refused class lives until a collection: keep it alive to look for it
    try:
        with pytest.raises(MessageDefinitionError):
            type("MsgRefused", (Message,), {"__annotations__": {"v": complex}})
        made = [c for c in Message.__subclasses__() if c.__qualname__ == "MsgRefused"]
        assert made  # msgspec made the class before it was checked
        assert not set(made) & set(all_messages())
        assert Codec.for_stack(1).message_classes == frozenset(all_messages())
    finally:
        gc.enable()


def test_all_messages_is_sorted_by_tag_and_sees_new_classes() -> None:
    before = all_messages()
    tags = [tag_of(cls) for cls in before]
    assert tags == sorted(tags)
    assert {MsgPing, MsgPingPlus, MsgRenamed, MsgFixedId} <= set(before)

    class MsgLate(Message):
        n: int

    assert set(all_messages()) == {*before, MsgLate}
    assert MsgLate in Codec.for_stack(1, None).message_classes
    assert Codec.for_stack(1, [MsgPing]).message_classes == {MsgPing}


# --- what cannot be a message ------------------------------------------------------------------


@pytest.mark.parametrize("header", HEADER_FIELDS)
@pytest.mark.parametrize("with_default", [False, True], ids=["no-default", "with-default"])
def test_a_field_named_like_the_header_is_refused(header: str, with_default: bool) -> None:
    namespace: dict[str, Any] = {"__annotations__": {"payload": int, header: int}}
    if with_default:
        namespace[header] = 7
    with pytest.raises(MessageDefinitionError, match=rf"MsgClash\.{header}: .*taken by the header"):
        type("MsgClash", (Message,), namespace)


class Thing:
    """Not a type any codec carries."""


class Empty(enum.Enum):
    """An enum without members."""


@pytest.mark.parametrize(
    ("annotation", "shown"),
    [
        pytest.param(Thing, "field 'bad': unsupported field type Thing", id="arbitrary-class"),
        pytest.param(object, "field 'bad': unsupported field type object", id="object"),
        pytest.param(complex, "field 'bad': unsupported field type complex", id="complex"),
        pytest.param(
            list[complex], "field 'bad': unsupported field type complex", id="nested-unsupported"
        ),
        pytest.param(
            dict[str, Thing], "field 'bad': unsupported field type Thing", id="dict-of-class"
        ),
        pytest.param(Empty, "at least one item", id="empty-enum"),
        pytest.param(
            Annotated[int, msgspec.Meta(ge=1), msgspec.Meta(ge=2)], "Multiple `Meta`", id="two-ge"
        ),
        pytest.param(
            Annotated[float, Finite, msgspec.Meta(ge=0)], "Multiple `Meta`", id="finite-and-ge"
        ),
        pytest.param(Annotated[str, msgspec.Meta(ge=0)], "numeric type", id="ge-on-str"),
        pytest.param(Annotated[int, msgspec.Meta(max_length=2)], "max_length", id="length-on-int"),
    ],
)
def test_a_field_type_that_cannot_travel_is_refused_naming_the_class(
    annotation: Any, shown: str
) -> None:
    namespace = {"__annotations__": {"ok": int, "bad": annotation}}
    with pytest.raises(MessageDefinitionError, match=r"^MsgUnsupported: ") as caught:
        type("MsgUnsupported", (Message,), namespace)
    assert shown in str(caught.value)


@pytest.mark.parametrize(
    "annotation",
    [
        pytest.param("NoSuchType", id="unknown-name"),
        pytest.param("list[NoSuchType]", id="unknown-inside"),
        pytest.param("MsgSelf | None", id="itself"),  # not bound yet when checked
    ],
)
def test_an_annotation_that_does_not_resolve_is_refused(annotation: str) -> None:
    with pytest.raises(MessageDefinitionError, match="MsgSelf: cannot resolve field annotations"):
        type("MsgSelf", (Message,), {"__annotations__": {"later": annotation}})


@pytest.mark.parametrize(
    "target",
    [
        pytest.param(type("PlainClass", (), {}), id="plain-class"),
        pytest.param(Message, id="message-base-itself"),
        pytest.param(3, id="not-a-class"),
        pytest.param(MsgType, id="enum-class"),
        pytest.param(msgspec.Struct, id="plain-struct"),
    ],
)
def test_at_message_refuses_what_is_not_a_message_class(target: Any) -> None:
    with pytest.raises(MessageDefinitionError, match="needs a subclass of Message"):
        message(target)


def test_struct_errors_become_definition_errors_naming_the_class() -> None:
    with pytest.raises(MessageDefinitionError, match="MsgBadOrder: Required field 'b'"):

        class MsgBadOrder(Message):
            a: int = 0
            b: int  # type: ignore[misc]


def test_wire_name_of_what_is_not_a_message_class_says_so() -> None:
    with pytest.raises(MessageDefinitionError, match="is not a message class"):
        wire_name(Thing)  # type: ignore[arg-type]


# --- instances: fields, header, match, equality, repr --------------------------------------------


def test_the_header_is_keyword_only_and_comes_after_the_fields() -> None:
    assert MsgPing.__struct_fields__ == ("n", "note", *HEADER_FIELDS)
    assert MsgPingPlus.__struct_fields__ == ("n", "note", "extra", *HEADER_FIELDS)
    assert message_fields(MsgPingPlus) == ("n", "note", "extra")
    assert MsgPing.__match_args__ == ("n", "note")
    ping = MsgPing(1, "x", msg_id=9, msg_type=MsgType.DENY, robot_id=4, corr_id=2)
    assert (ping.msg_id, ping.msg_type, ping.robot_id, ping.corr_id) == (9, MsgType.DENY, 4, 2)
    with pytest.raises(TypeError, match="positional"):
        MsgPing(1, "x", 9)  # type: ignore[misc]
    assert not hasattr(ping, "__dict__")


def test_fields_are_positional_in_declaration_order_bases_first() -> None:
    assert MsgPing(3) == MsgPing(n=3, note="")
    assert MsgPingPlus(1, "a", b"x") == MsgPingPlus(n=1, note="a", extra=b"x")
    ping = MsgPing(3)
    assert ping.msg_type is MsgType.ACCEPT
    assert [getattr(ping, name) for name in HEADER_FIELDS[1:]] == [0] * 5
    assert MsgDecorated().items == []
    assert MsgDecorated().items is not MsgDecorated().items


def describe(msg: Message) -> str:
    match msg:
        case MsgPingPlus(n, extra=extra):
            return f"plus {n} {extra!r}"
        case MsgPing(n=0):
            return "zero"
        case MsgPing(n, note) if note:
            return f"ping {n} {note}"
        case MsgPing(n=n, msg_type=MsgType.NEGOTIATION):
            return f"asked {n}"
        case MsgRenamed(value=value):
            return f"renamed {value}"
    return "other"


@pytest.mark.parametrize(
    ("msg", "expected"),
    [
        pytest.param(MsgPingPlus(1, extra=b"x"), "plus 1 b'x'", id="subclass-first"),
        pytest.param(MsgPing(0), "zero", id="literal"),
        pytest.param(MsgPing(2, "hi"), "ping 2 hi", id="positional"),
        pytest.param(MsgPing(3, msg_type=MsgType.NEGOTIATION), "asked 3", id="header-keyword"),
        pytest.param(MsgRenamed(0.5), "renamed 0.5", id="renamed-class"),
        pytest.param(MsgFixedId(), "other", id="no-case"),
    ],
)
def test_match_with_class_patterns(msg: Message, expected: str) -> None:
    assert describe(msg) == expected


@pytest.mark.parametrize(
    ("one", "other", "equal"),
    [
        pytest.param(MsgPing(1), MsgPing(1), True, id="same"),
        pytest.param(MsgPing(1), MsgPing(2), False, id="field"),
        pytest.param(MsgPing(1), MsgPing(1, msg_id=1), False, id="msg-id"),
        pytest.param(MsgPing(1), MsgPing(1, msg_type=MsgType.DENY), False, id="msg-type"),
        pytest.param(MsgPing(1, corr_id=3), MsgPing(1, corr_id=3), True, id="same-header"),
        pytest.param(MsgPing(1), MsgPingPlus(1), False, id="subclass"),
    ],
)
def test_equality_includes_the_header(one: Message, other: Message, equal: bool) -> None:
    assert (one == other) is equal


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


def test_msg_type_values_and_the_header_order_are_wire_stable() -> None:
    assert [(member.name, member.value) for member in MsgType] == [
        ("NEGOTIATION", 0),
        ("ACCEPT", 1),
        ("DENY", 2),
    ]
    assert all(isinstance(member, int) and MsgType(int(member)) is member for member in MsgType)
    assert HEADER_FIELDS == ("msg_type", "msg_id", "robot_id", "src_layer", "dst_layer", "corr_id")
