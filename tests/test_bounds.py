"""Bounds on message fields: declared with Annotated, checked by the decoder, counted."""

from __future__ import annotations

import math
from typing import Annotated, Any

import msgpack
import pytest

import cas_async
from cas_async import (
    Bounds,
    DecodeError,
    Finite,
    Layer,
    Message,
    MessageDefinitionError,
    Robot,
    Swarm,
    VirtualClock,
    message,
    spec_of,
)
from cas_async.transport import Codec
from tests.taps import Tap


@message
class Sighting(Message):
    x: Annotated[float, Finite]
    speed: Annotated[float, Finite, Bounds(ge=0)]
    seats: Annotated[int, Bounds(ge=1, le=8)] = 1
    path: list[Annotated[float, Finite]] | None = None


@message
class Unbounded(Message):
    x: float


CODEC = Codec.for_stack(1, [Sighting, Unbounded])


def raw(*fields: Any, msg_id: int = 5, corr_id: int = 0, cls: type[Message] = Sighting) -> bytes:
    """A datagram of ``cls`` with these fields, header as given, bypassing the encoder."""
    header = [CODEC.fingerprint, spec_of(cls).type_id, msg_id, 1, 2, 0, 0, corr_id]
    return msgpack.packb([*header, *fields])


def test_values_within_the_bounds_decode_on_both_paths() -> None:
    fast = CODEC.decode(raw(1.5, 0.0, 8, None))
    precise = CODEC.decode(raw(1.5, 0.0, 8, [1.0, -2.0]))  # a list: still the fast path
    assert (fast.x, fast.speed, fast.seats) == (1.5, 0.0, 8)  # type: ignore[attr-defined]
    assert precise.path == [1.0, -2.0]  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("fields", "match"),
    [
        pytest.param((math.nan, 1.0, 1, None), r"Sighting\.x: expected float\(finite\)", id="nan"),
        pytest.param((math.inf, 1.0, 1, None), r"Sighting\.x", id="inf"),
        pytest.param(
            (0.0, -1.0, 1, None), r"Sighting\.speed: expected float\(finite,>=0\)", id="below"
        ),
        pytest.param((0.0, math.nan, 1, None), r"Sighting\.speed", id="nan-under-a-bound"),
        pytest.param(
            (0.0, 1.0, 9, None), r"Sighting\.seats: expected int\(>=1,<=8\), got 9", id="above"
        ),
        pytest.param((0.0, 1.0, 0, None), r"Sighting\.seats", id="int-below"),
        pytest.param((0.0, 1.0, 1, [1.0, math.nan]), r"Sighting\.path\[1\]", id="an-element"),
    ],
)
def test_a_value_outside_its_bounds_is_refused_naming_the_field(
    fields: tuple[Any, ...], match: str
) -> None:
    with pytest.raises(DecodeError, match=match) as caught:
        CODEC.decode(raw(*fields))
    assert caught.value.reason == "out_of_range"


@pytest.mark.parametrize("bad", [math.inf, -math.inf, math.nan])
def test_a_long_list_with_one_bad_element_is_refused_in_msgspec_s_words(bad: float) -> None:
    path = [1.0] * 5000 + [bad]
    with pytest.raises(DecodeError, match=r"Sighting\.path\[5000\]") as caught:
        CODEC.decode(raw(0.0, 1.0, 1, path))
    assert caught.value.reason == "out_of_range"
    assert str(caught.value).endswith("expected float(finite)")  # not "<= 1.79e308"


@pytest.mark.parametrize(("msg_id", "corr_id"), [(-1, 0), (5, -1), (-(2**63), 0)])
def test_negative_ids_in_the_header_are_refused(msg_id: int, corr_id: int) -> None:
    with pytest.raises(DecodeError, match="must be >= 0") as caught:
        CODEC.decode(raw(1.0, msg_id=msg_id, corr_id=corr_id, cls=Unbounded))
    assert caught.value.reason == "bad_header"


def test_bounds_are_part_of_the_schema_and_so_of_the_fingerprint() -> None:
    spec = spec_of(Sighting)
    assert "x:float(finite)" in spec.schema
    assert "speed:float(finite,>=0)" in spec.schema
    assert "seats:int(>=1,<=8)" in spec.schema
    assert "x:float" in spec_of(Unbounded).schema


@pytest.mark.parametrize(
    ("make", "match"),
    [
        pytest.param(lambda: Bounds(ge=math.nan), "Bounds.ge must be a number", id="nan-bound"),
        pytest.param(lambda: Bounds(ge=2, le=1), "leaves no value", id="empty"),
        pytest.param(lambda: Bounds(gt=1, lt=1), "leaves no value", id="empty-open"),
    ],
)
def test_impossible_bounds_are_refused(make: Any, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        make()


def test_bounds_on_a_field_that_is_not_a_number_are_refused() -> None:
    with pytest.raises(MessageDefinitionError, match="Bounds apply to int and float fields"):

        @message
        class BadBounds(Message):
            name: Annotated[str, Bounds(ge=0)]


def test_several_bounds_on_one_field_all_apply() -> None:
    both = Bounds(ge=0) & Bounds(le=10) & Finite
    assert both == Bounds(ge=0, le=10, finite=True)
    assert [both.admits(v) for v in (-1, 0, 10, 11, math.nan)] == [False, True, True, False, False]


def test_a_robot_counts_what_its_bounds_refuse_and_no_layer_sees_it() -> None:
    seen: list[Message] = []

    class Watcher(Layer):
        async def handle_msg(self, msg: Message) -> None:
            seen.append(msg)

    async def main() -> dict[str, int]:
        clock, tap = VirtualClock(), Tap()
        robots = [
            Robot(i, [Watcher()], transport=tap, clock=clock, messages=[Sighting, Unbounded])
            for i in (1, 2)
        ]
        async with Swarm(robots):
            for fields in ((math.nan, 1.0, 1, None), (1.0, 2.0, 3, None)):
                header = [
                    CODEC.fingerprint,
                    spec_of(Sighting).type_id,
                    len(seen) + 10,
                    1,
                    2,
                    0,
                    0,
                    0,
                ]
                tap.deliver(1, msgpack.packb([*header, *fields]), 2)
            await clock.sleep(1.0)
            return robots[0].dropped

    assert cas_async.run(main(), virtual=True) == {"decode.out_of_range": 1}
    assert [m.speed for m in seen] == [2.0]  # type: ignore[attr-defined]
