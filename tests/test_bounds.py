"""Bounds on message fields: msgspec.Meta, Finite and finite(), checked on arrival and counted."""

from __future__ import annotations

import math
from typing import Annotated, Any

import msgspec
import pytest

from cas_async import DecodeError, Finite, Message, MessageDefinitionError, finite
from cas_async.testing import Recorder, Robots, run_until
from cas_async.transport import Codec
from tests.taps import Tap
from tests.wire import datagram


class Sighting(Message):
    x: Annotated[float, Finite]
    speed: Annotated[float, finite(ge=0)]
    share: Annotated[float, finite(gt=0, lt=1)] = 0.5
    seats: Annotated[int, msgspec.Meta(ge=1, le=8)] = 1
    path: list[Annotated[float, Finite]] | None = None
    label: Annotated[str, msgspec.Meta(max_length=4, pattern="^[a-z]*$")] = ""
    few: Annotated[list[int], msgspec.Meta(max_length=2)] = msgspec.field(default_factory=list)
    step: Annotated[int, msgspec.Meta(multiple_of=2)] = 0


class Unbounded(Message):
    x: float


MESSAGES = [Sighting, Unbounded]
CODEC = Codec.for_stack(1, MESSAGES)
OK = (1.5, 0.0, 0.5, 8, None, "", [], 0)  # every Sighting field within its bounds
NAMES = ("x", "speed", "share", "seats", "path", "label", "few", "step")


def sighting(msg_id: int = 1, **changes: Any) -> bytes:
    """A Sighting datagram with these fields changed from ``OK``, bypassing the encoder."""
    values = dict(zip(NAMES, OK, strict=True)) | changes
    fields = [values[name] for name in NAMES]
    return datagram(CODEC.fingerprint, Sighting, fields, msg_id=msg_id, robot_id=2)


def test_values_within_the_bounds_decode() -> None:
    decoded = CODEC.decode(sighting(path=[1.0, -2.0], label="abcd", share=1e-300, few=[1, 2]))
    assert isinstance(decoded, Sighting)
    assert (decoded.x, decoded.speed, decoded.seats, decoded.path) == (1.5, 0.0, 8, [1.0, -2.0])
    assert CODEC.decode(sighting(x=-1e308, speed=1e308)) == Sighting(
        -1e308, 1e308, seats=8, msg_id=1, robot_id=2
    )


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        pytest.param({"x": math.nan}, r"^Sighting\.x: Expected a finite `float`$", id="nan"),
        pytest.param({"x": math.inf}, r"^Sighting\.x: Expected a finite `float`$", id="inf"),
        pytest.param({"x": -math.inf}, r"^Sighting\.x: Expected a finite `float`$", id="-inf"),
        pytest.param({"speed": -1.0}, r"^Sighting\.speed: Expected `float` >= 0", id="below"),
        pytest.param({"speed": -5e-324}, r"^Sighting\.speed: ", id="just-below"),
        pytest.param({"speed": math.nan}, r"^Sighting\.speed: ", id="nan-under-ge"),
        pytest.param({"speed": math.inf}, r"^Sighting\.speed: .*finite `float`", id="inf-under-ge"),
        pytest.param({"share": 0.0}, r"^Sighting\.share: Expected `float` > 0", id="open-low"),
        pytest.param({"share": 1.0}, r"^Sighting\.share: Expected `float` < 1", id="open-high"),
        pytest.param({"seats": 9}, r"^Sighting\.seats: Expected `int` <= 8$", id="int-above"),
        pytest.param({"seats": 0}, r"^Sighting\.seats: Expected `int` >= 1$", id="int-below"),
        pytest.param({"path": [1.0, math.nan]}, r"^Sighting\.path\[1\]: .*finite", id="item"),
        pytest.param({"label": "abcde"}, r"^Sighting\.label: .*length <= 4", id="too-long"),
        pytest.param({"label": "AB"}, r"^Sighting\.label: .*matching regex", id="pattern"),
        pytest.param({"few": [1, 2, 3]}, r"^Sighting\.few: .*length <= 2", id="too-many"),
        pytest.param({"step": 3}, r"^Sighting\.step: .*multiple of 2", id="multiple-of"),
    ],
)
def test_a_value_outside_its_bounds_is_refused_naming_the_field(
    changes: dict[str, Any], match: str
) -> None:
    with pytest.raises(DecodeError, match=match) as caught:
        CODEC.decode(sighting(**changes))
    assert caught.value.reason == "out_of_range"


@pytest.mark.parametrize("bad", [math.inf, -math.inf, math.nan], ids=["inf", "-inf", "nan"])
def test_one_bad_item_in_a_long_list_is_refused_in_plain_words(bad: float) -> None:
    with pytest.raises(DecodeError, match=r"^Sighting\.path\[5000\]: ") as caught:
        CODEC.decode(sighting(path=[1.0] * 5000 + [bad]))
    assert caught.value.reason == "out_of_range"
    assert str(caught.value).endswith("Expected a finite `float`")  # not "<= 1.797...e+308"


def test_an_unbounded_float_takes_nan_and_infinities() -> None:
    for value in (math.nan, math.inf, -math.inf):
        decoded = CODEC.decode(datagram(CODEC.fingerprint, Unbounded, [value]))
        assert isinstance(decoded, Unbounded)
        assert not math.isfinite(decoded.x)


@pytest.mark.parametrize(
    "header",
    [
        pytest.param({"msg_id": -1}, id="msg-id"),
        pytest.param({"corr_id": -1}, id="corr-id"),
        pytest.param({"msg_id": -(2**63)}, id="msg-id-min"),
    ],
)
def test_negative_ids_in_the_header_are_refused(header: dict[str, int]) -> None:
    data = datagram(CODEC.fingerprint, Unbounded, [1.0], **header)
    with pytest.raises(
        DecodeError, match=r"bad header: Unbounded\.(msg|corr)_id: .* >= 0"
    ) as caught:
        CODEC.decode(data)
    assert caught.value.reason == "bad_header"


class Wider(Message):
    x: Annotated[float, finite(ge=-1)]


class Narrower(Message):
    x: Annotated[float, finite(ge=0)]


class Open(Message):
    x: Annotated[float, finite(gt=0)]


class Plain(Message):
    x: float


@pytest.mark.parametrize(
    ("one", "other"),
    [
        pytest.param(Plain, Wider, id="bound-or-none"),
        pytest.param(Wider, Narrower, id="another-bound"),
        pytest.param(Narrower, Open, id="ge-or-gt"),
    ],
)
def test_bounds_are_part_of_the_fingerprint(one: type[Message], other: type[Message]) -> None:
    # The classes differ in their names too: compare each with its bound as the only change.
    def alike(cls: type[Message]) -> int:
        renamed = type(
            "Same", (Message,), {"__annotations__": {"x": cls.__annotations__["x"]}}
        )  # one name, one tag: only the bound differs
        return Codec.for_stack(1, [renamed]).fingerprint

    assert alike(one) != alike(other)
    assert alike(one) == alike(one)


@pytest.mark.parametrize(
    "annotation",
    [
        pytest.param(Annotated[int, msgspec.Meta(ge=2, le=1)], id="int-ge-above-le"),
        pytest.param(Annotated[int, msgspec.Meta(gt=1, lt=2)], id="int-nothing-between"),
        pytest.param(Annotated[float, msgspec.Meta(gt=1, lt=1)], id="float-open-point"),
        pytest.param(Annotated[float, msgspec.Meta(ge=1, lt=1)], id="float-half-open-point"),
        pytest.param(Annotated[float, finite(ge=2, le=1)], id="finite-empty"),
        pytest.param(list[Annotated[int, msgspec.Meta(ge=5, le=0)]], id="inside-a-list"),
        pytest.param(Annotated[str, msgspec.Meta(min_length=3, max_length=2)], id="lengths"),
    ],
)
def test_bounds_that_leave_no_value_are_refused_when_the_class_is_defined(annotation: Any) -> None:
    with pytest.raises(MessageDefinitionError, match=r"^Impossible: field 'v': .*leave no value"):
        type("Impossible", (Message,), {"__annotations__": {"v": annotation}})


@pytest.mark.parametrize(
    "annotation",
    [
        pytest.param(Annotated[int, msgspec.Meta(ge=1, le=1)], id="int-one-value"),
        pytest.param(Annotated[int, msgspec.Meta(gt=1, lt=3)], id="int-open"),
        pytest.param(Annotated[float, msgspec.Meta(ge=1, le=1)], id="float-one-value"),
        pytest.param(Annotated[str, msgspec.Meta(min_length=2, max_length=2)], id="lengths"),
    ],
)
def test_narrow_bounds_that_leave_a_value_are_accepted(annotation: Any) -> None:
    assert type("Narrow", (Message,), {"__annotations__": {"v": annotation}})


@pytest.mark.parametrize(
    ("make", "match"),
    [
        pytest.param(lambda: finite(ge=0, gt=0), "ge or gt", id="ge-and-gt"),
        pytest.param(lambda: finite(le=0, lt=0), "le or lt", id="le-and-lt"),
        pytest.param(lambda: finite(ge=math.nan), "finite", id="nan-bound"),
    ],
)
def test_finite_refuses_contradictory_arguments(make: Any, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        make()


def test_conflicting_bounds_on_one_field_are_refused() -> None:
    with pytest.raises(MessageDefinitionError, match=r"Conflict: .*Multiple `Meta`"):
        type(
            "Conflict",
            (Message,),
            {"__annotations__": {"v": Annotated[float, Finite, msgspec.Meta(ge=0)]}},
        )


@pytest.mark.asyncio
@pytest.mark.cas_virtual
async def test_a_robot_counts_what_its_bounds_refuse_and_no_layer_sees_it(
    cas_robots: Robots,
) -> None:
    cas_robots.allowed_drops.add("decode.out_of_range")
    tap = Tap()
    listener = Recorder()
    robot = await cas_robots.start(1, [listener], transport=tap, messages=MESSAGES)
    await cas_robots.start(2, [Recorder()], transport=tap, messages=MESSAGES)
    refused = [{"x": math.nan}, {"speed": -1.0}, {"seats": 9}, {"path": [math.inf]}]
    for msg_id, changes in enumerate([*refused, {"speed": 2.0}], start=10):
        tap.deliver(1, sighting(msg_id, **changes), 2)  # from robot 2, as its header says
    await run_until(lambda: listener.arrived, timeout=10)
    await run_until(lambda: sum(robot.dropped.values()) == len(refused), timeout=10)
    assert robot.dropped == {"decode.out_of_range": len(refused)}
    (seen,) = listener.arrived
    assert isinstance(seen, Sighting)
    assert seen.speed == 2.0
