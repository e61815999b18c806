"""strategy_for: Hypothesis strategies from message classes, through the real codec."""

from __future__ import annotations

import enum
import math
from typing import Annotated

import msgspec
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from apps.fire_brigade.messages import MESSAGES
from cas_async import Finite, Message, finite
from cas_async.testing import assert_roundtrip, strategy_for


class Colour(enum.IntEnum):
    RED = 1
    BLUE = 7


class Inner(Message):
    x: float
    tag: str = ""


class Point(msgspec.Struct, frozen=True):
    x: float
    y: float


class KitchenSink(Message):
    n: int
    ok: bool
    name: str
    blob: bytes
    ratio: float
    colour: Colour
    inner: Inner
    maybe: int | None
    ints: list[int]
    pair: tuple[int, str]
    many: tuple[float, ...]
    table: dict[str, list[int]]
    bare: list  # type: ignore[type-arg]
    bare_map: dict  # type: ignore[type-arg]
    grid: np.ndarray  # type: ignore[type-arg]
    finite: Annotated[float, Finite]
    seats: Annotated[int, msgspec.Meta(ge=1, le=8)]
    share: Annotated[float, msgspec.Meta(gt=0, lt=1)]
    few: Annotated[int, msgspec.Meta(gt=0, lt=3)]
    speed: Annotated[float, finite(gt=0)]
    point: Point
    points: list[Point]


SINK_MESSAGES = [KitchenSink, Inner]


@pytest.mark.slow  # a few seconds: the fast suite stays under 2 minutes
@settings(max_examples=150, deadline=None)
@given(strategy_for(KitchenSink))
def test_every_kind_of_field_survives_the_codec(msg: KitchenSink) -> None:
    assert_roundtrip(msg, messages=SINK_MESSAGES)


@pytest.mark.slow
@settings(max_examples=100, deadline=None)
@given(st.data())
def test_the_fire_brigade_messages_survive_the_codec(data: st.DataObject) -> None:
    cls = data.draw(st.sampled_from(MESSAGES))
    msg = data.draw(strategy_for(cls))
    assert_roundtrip(msg, layers=5, messages=MESSAGES)


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(strategy_for(KitchenSink))
def test_drawn_values_keep_their_bounds(msg: KitchenSink) -> None:
    assert math.isfinite(msg.finite)
    assert 1 <= msg.seats <= 8
    assert 0 < msg.share < 1
    assert msg.few in (1, 2)
    assert msg.colour in (Colour.RED, Colour.BLUE)
    assert 0 < msg.speed < math.inf


def test_a_class_without_message_is_refused() -> None:
    class Plain:
        x: int

    with pytest.raises(TypeError):
        strategy_for(Plain)  # type: ignore[arg-type]
