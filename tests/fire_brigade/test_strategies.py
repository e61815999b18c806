"""Partner selection: each strategy's ``choose`` on hand-made SearchViews, and naming them.

A strategy is a layer, but ``choose`` is a pure function of the view (and, for the
random strategy, of its seeded generator), so these tests create strategies
without a robot. Expected orders are worked out with ``estimate.delivery_time``,
the metric the thesis's time strategy ranks by (§5.2).
"""

from __future__ import annotations

import dataclasses
import itertools
import re

import pytest

from apps.fire_brigade import (
    Candidate,
    RandomStrategy,
    SearchView,
    SinkFirstStrategy,
    SoloStrategy,
    Strategy,
    TimeGainStrategy,
    TimeStrategy,
)
from apps.fire_brigade.base import Params, Point
from apps.fire_brigade.estimate import delivery_time, solo_time
from apps.fire_brigade.messages import Kind
from apps.fire_brigade.strategies import STRATEGY_NAMES, strategy_class
from cas_async import ConstantSpeed, Decelerating, SpeedProfile

SINK = 2
SINK_AT: Point = (5.0, 19.0)
HERE: Point = (5.0, 1.0)

# Carrying a bucket 18 units at 5 slowing by 1 down to 1: 12 units in the first
# 4 s (5*4 - 16/2), the last 6 at speed 1: 10 s alone.
FRESH_CARRIER = Decelerating(5.0, 1.0, 1.0)
# Already at the floor: 18 s alone, so almost any partner helps.
TIRED_CARRIER = Decelerating(1.0, 1.0, 1.0)

# Candidate partners around HERE = (5, 1), the sink straight up at (5, 19).
BEHIND = Candidate(11, (5.0, -2.0))  # 3 behind: walks to meet, then carries 3 farther
AHEAD = Candidate(12, (5.0, 5.0))  # 4 ahead, on the way: the best
LEFT = Candidate(13, (2.0, 4.0))  # ahead and aside, mirror images of each other:
RIGHT = Candidate(14, (8.0, 4.0))  # the same score, so the lower id goes first
ASIDE = Candidate(15, (9.0, 1.0))  # level with the carrier
CLOSE_BEHIND = Candidate(16, (5.0, 0.0))
SAME_SPOT = Candidate(17, HERE)  # a fresh partner here only equals carrying it oneself
AROUND = (SAME_SPOT, CLOSE_BEHIND, BEHIND, LEFT, RIGHT, ASIDE, AHEAD)  # nearest first


def params(kind: Kind = Kind.TRANSPORTER, **changes: object) -> Params:
    base = Params(
        kind=kind,
        peers=tuple(range(1, 20)),
        world=(10.0, 20.0),
        speed=5.0,
        deceleration=1.0,
        min_speed=1.0,
        handover_time=0.5,
        range=5.0,
        search_step=1.0,
        retry_interval=1.0,
        search_growth=2.0,
        seed=1234,
    )
    return dataclasses.replace(base, **changes)  # type: ignore[arg-type]


def view(
    candidates: tuple[Candidate, ...] = AROUND,
    *,
    kind: Kind = Kind.TRANSPORTER,
    carrying: SpeedProfile | None = FRESH_CARRIER,
    here: Point = HERE,
    p: Params | None = None,
) -> SearchView:
    if kind is not Kind.TRANSPORTER:
        carrying = None  # stations cannot carry
    return SearchView(
        robot=1,
        kind=kind,
        here=here,
        carrying=carrying,
        sink=SINK,
        sink_at=SINK_AT,
        candidates=candidates,
        params=p or params(kind),
    )


def score(v: SearchView, candidate: Candidate) -> float:
    """The time strategy's metric, straight from the estimate module."""
    return delivery_time(
        v.here, v.carrying, candidate.at, v.fresh_partner, v.loaded_partner, v.sink_at
    )


def by_time(v: SearchView, candidates: tuple[Candidate, ...]) -> list[int]:
    return [c.robot for c in sorted(candidates, key=lambda c: (score(v, c), c.robot))]


def to_sink(v: SearchView) -> float:
    """The time strategy's score of the sink: the time to drive the bucket there."""
    return delivery_time(v.here, v.carrying, SINK_AT, None, None, SINK_AT)


# -- the view ----------------------------------------------------------------------------


def test_view_profiles_of_a_partner_come_from_the_params() -> None:
    v = view(p=params(speed=3.0, deceleration=0.5, min_speed=0.6))
    assert v.fresh_partner == ConstantSpeed(3.0)
    assert v.loaded_partner == Decelerating(3.0, 0.5, 0.6)


def test_view_finds_the_sink_among_the_candidates() -> None:
    sink = Candidate(SINK, SINK_AT)
    assert view((AHEAD, sink)).sink_in_range() == sink
    assert view((AHEAD, BEHIND)).sink_in_range() is None
    assert view(()).sink_in_range() is None


def test_the_base_strategy_has_no_choice_of_its_own() -> None:
    class Unfinished(Strategy):
        pass

    with pytest.raises(NotImplementedError, match="Unfinished must implement choose"):
        Unfinished(params()).choose(view())


# -- time (§5.2 as written) --------------------------------------------------------------


def test_time_ranks_the_sink_like_any_other_robot_in_range() -> None:
    sink = Candidate(SINK, SINK_AT)
    v = view((AHEAD, LEFT, BEHIND, sink))
    chosen = TimeStrategy(params()).choose(v)
    assert sorted(chosen) == sorted([AHEAD.robot, LEFT.robot, BEHIND.robot, SINK])
    # A fresh carrier 18 units away: driving there itself (10 s) loses to a partner
    # ahead (AHEAD, LEFT) and beats one behind.
    assert to_sink(v) == pytest.approx(10.0)
    assert score(v, AHEAD) < score(v, LEFT) < to_sink(v) < score(v, BEHIND)
    assert chosen == [AHEAD.robot, LEFT.robot, SINK, BEHIND.robot]


def test_time_asks_the_sink_first_when_it_is_the_soonest() -> None:
    near_sink: Point = (5.0, 17.0)
    sink = Candidate(SINK, SINK_AT)
    v = view((Candidate(12, (5.0, 14.0)), sink), here=near_sink)
    assert TimeStrategy(params()).choose(v) == [SINK, 12]


def test_time_asks_partners_slower_than_carrying_it_itself_last() -> None:
    v = view()  # a fresh carrier: 10 s alone, yet everyone in range is asked
    chosen = TimeStrategy(params()).choose(v)
    assert chosen == by_time(v, AROUND)
    assert sorted(chosen) == sorted(c.robot for c in AROUND)
    alone = solo_time(HERE, FRESH_CARRIER, SINK_AT)
    assert score(v, BEHIND) > alone  # carrying it would be sooner: asked all the same


def test_time_with_nobody_in_range_asks_nobody() -> None:
    assert TimeStrategy(params()).choose(view(())) == []


def test_time_ranks_partners_by_delivery_time() -> None:
    v = view(carrying=TIRED_CARRIER)  # everyone beats 18 s alone
    chosen = TimeStrategy(params()).choose(v)
    assert chosen == by_time(v, AROUND)
    assert chosen[0] == AHEAD.robot  # not the nearest: the one on the way to the sink
    scores = [score(v, c) for c in sorted(AROUND, key=lambda c: chosen.index(c.robot))]
    assert scores == sorted(scores)


def test_time_breaks_ties_by_robot_id() -> None:
    v = view((RIGHT, LEFT), carrying=TIRED_CARRIER)
    assert score(v, LEFT) == score(v, RIGHT)
    assert TimeStrategy(params()).choose(v) == [LEFT.robot, RIGHT.robot]


@pytest.mark.slow
def test_time_ignores_the_order_candidates_come_in() -> None:
    strategy = TimeStrategy(params())
    orders = {tuple(strategy.choose(view(order))) for order in itertools.permutations(AROUND)}
    assert len(orders) == 1


# -- time gain ---------------------------------------------------------------------------


def test_time_gain_ranks_the_sink_but_skips_partners_slower_than_carrying() -> None:
    sink = Candidate(SINK, SINK_AT)
    v = view((AHEAD, LEFT, BEHIND, ASIDE, sink))
    # BEHIND and ASIDE lose to carrying it (10 s); the sink costs exactly that.
    assert TimeGainStrategy(params()).choose(v) == [AHEAD.robot, LEFT.robot, SINK]


def test_time_gain_near_the_sink_asks_the_sink_first() -> None:
    sink = Candidate(SINK, SINK_AT)
    v = view((Candidate(12, (5.0, 14.0)), sink), here=(5.0, 17.0))
    assert TimeGainStrategy(params()).choose(v) == [SINK]


def test_time_gain_for_a_generator_is_the_time_rule() -> None:
    v = view(kind=Kind.GENERATOR)
    p = params(Kind.GENERATOR)
    assert TimeGainStrategy(p).choose(v) == TimeStrategy(p).choose(v)


# -- sink first (this demo's earlier rule) -------------------------------------------------


def test_sink_first_asks_only_the_sink_when_it_is_in_range() -> None:
    sink = Candidate(SINK, SINK_AT)
    # The sink is the farthest candidate, yet handing it the bucket is delivering it.
    assert SinkFirstStrategy(params()).choose(view((AHEAD, LEFT, sink))) == [SINK]
    assert SinkFirstStrategy(params()).choose(view((sink,), carrying=TIRED_CARRIER)) == [SINK]


def test_sink_first_ranks_by_time_like_the_time_strategy() -> None:
    v = view(carrying=TIRED_CARRIER)  # everyone beats 18 s alone
    assert SinkFirstStrategy(params()).choose(v) == TimeStrategy(params()).choose(v)


def test_a_transporter_skips_partners_slower_than_carrying_it_itself() -> None:
    v = view()  # a fresh carrier: 10 s alone
    alone = solo_time(HERE, FRESH_CARRIER, SINK_AT)
    assert alone == pytest.approx(10.0)
    chosen = SinkFirstStrategy(params()).choose(v)
    assert chosen == [AHEAD.robot, LEFT.robot, RIGHT.robot]
    assert all(score(v, c) < alone for c in (AHEAD, LEFT, RIGHT))
    # Behind, level, or right here (a fresh partner with the same fatigue ahead of it
    # is exactly as fast, not faster): carrying it is at least as quick.
    for skipped in (BEHIND, ASIDE, CLOSE_BEHIND, SAME_SPOT):
        assert score(v, skipped) >= alone


def test_a_transporter_with_nobody_faster_asks_nobody() -> None:
    assert SinkFirstStrategy(params()).choose(view((BEHIND, ASIDE, SAME_SPOT))) == []
    assert SinkFirstStrategy(params()).choose(view(())) == []


def test_fatigue_makes_more_partners_worth_asking() -> None:
    strategy = SinkFirstStrategy(params())
    fresh = strategy.choose(view())
    tired = strategy.choose(view(carrying=TIRED_CARRIER))
    assert set(fresh) < set(tired)


@pytest.mark.parametrize("strategy", [TimeStrategy, SinkFirstStrategy])
def test_a_generator_cannot_carry_so_it_ranks_everyone_in_range(
    strategy: type[Strategy],
) -> None:
    v = view(kind=Kind.GENERATOR)
    assert v.carrying is None
    chosen = strategy(params(Kind.GENERATOR)).choose(v)
    assert sorted(chosen) == sorted(c.robot for c in AROUND)
    assert chosen == by_time(v, AROUND)
    # The partner meets it where it stands, so the nearest partner is the best.
    assert chosen[0] == SAME_SPOT.robot


# -- random ------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2, 1234, 2**62])
def test_random_is_a_permutation_of_the_candidates(seed: int) -> None:
    strategy = RandomStrategy(params(seed=seed))
    for _ in range(20):
        chosen = strategy.choose(view())
        assert sorted(chosen) == sorted(c.robot for c in AROUND)


def test_random_is_reproducible_for_a_seed() -> None:
    def orders(seed: int, kind: Kind = Kind.TRANSPORTER) -> list[list[int]]:
        strategy = RandomStrategy(params(kind, seed=seed))
        return [strategy.choose(view(kind=kind)) for _ in range(10)]

    assert orders(7) == orders(7)
    assert orders(7) != orders(8)
    assert orders(7, Kind.GENERATOR) == orders(7)  # the kind does not change the draw
    assert len({tuple(order) for order in orders(7)}) > 1  # a new draw each time


def test_random_does_not_rank_by_time() -> None:
    strategy = RandomStrategy(params(seed=5))
    timed = TimeStrategy(params()).choose(view(carrying=TIRED_CARRIER))
    draws = [strategy.choose(view(carrying=TIRED_CARRIER)) for _ in range(20)]
    assert any(draw != timed for draw in draws)
    # ... and, unlike the sink-first rule, it also asks partners slower than carrying.
    assert all(BEHIND.robot in draw for draw in draws)


def test_random_asks_only_the_sink_when_it_is_in_range() -> None:
    sink = Candidate(SINK, SINK_AT)
    strategy = RandomStrategy(params(seed=3))
    assert all(strategy.choose(view((*AROUND, sink))) == [SINK] for _ in range(10))


def test_random_with_nobody_in_range_asks_nobody() -> None:
    assert RandomStrategy(params()).choose(view(())) == []


# -- solo --------------------------------------------------------------------------------


def test_a_solo_transporter_asks_only_the_sink() -> None:
    sink = Candidate(SINK, SINK_AT)
    strategy = SoloStrategy(params())
    assert strategy.choose(view((*AROUND, sink))) == [SINK]
    assert strategy.choose(view((sink,))) == [SINK]


def test_a_solo_transporter_carries_on_even_when_partners_are_faster() -> None:
    v = view(carrying=TIRED_CARRIER)
    assert TimeStrategy(params()).choose(v)  # collaboration would help...
    assert SoloStrategy(params()).choose(v) == []  # ...but solo carries it


def test_a_solo_generator_ranks_by_time() -> None:
    v = view(kind=Kind.GENERATOR)
    chosen = SoloStrategy(params(Kind.GENERATOR)).choose(v)
    assert chosen == TimeStrategy(params(Kind.GENERATOR)).choose(v)
    assert chosen == by_time(v, AROUND)


# -- naming a strategy -------------------------------------------------------------------


class Nearest(Strategy):
    """A user's strategy: the nearest candidate first (candidates come nearest first)."""

    def choose(self, view: SearchView) -> list[int]:
        return [candidate.robot for candidate in view.candidates]


@pytest.mark.parametrize(
    ("name", "cls"),
    [
        pytest.param("time", TimeStrategy, id="time"),
        pytest.param("random", RandomStrategy, id="random"),
        pytest.param("solo", SoloStrategy, id="solo"),
        pytest.param("sink_first", SinkFirstStrategy, id="sink_first"),
        pytest.param("time_gain", TimeGainStrategy, id="time_gain"),
        pytest.param("apps.fire_brigade:SoloStrategy", SoloStrategy, id="built-in-by-path"),
        pytest.param("tests.fire_brigade.test_strategies:Nearest", Nearest, id="user-class"),
    ],
)
def test_strategy_class_resolves_names(name: str, cls: type[Strategy]) -> None:
    assert strategy_class(name) is cls


def test_the_built_in_names() -> None:
    assert STRATEGY_NAMES == ("time", "random", "solo", "time_gain", "sink_first")


def test_a_user_strategy_chooses_through_the_same_view() -> None:
    assert strategy_class("tests.fire_brigade.test_strategies:Nearest")(params()).choose(
        view()
    ) == [c.robot for c in AROUND]


@pytest.mark.parametrize(
    ("name", "message"),
    [
        pytest.param(
            "Time", "expected one of time, random, solo, time_gain, sink_first", id="case-matters"
        ),
        pytest.param("tests.fire_brigade.test_strategies", "'package.module:Class'", id="no-class"),
        pytest.param(":Nearest", "'package.module:Class'", id="no-module"),
        pytest.param("no_such_module:X", "cannot import 'no_such_module'", id="no-module-found"),
        pytest.param("apps.fire_brigade:Missing", "is not a subclass", id="no-such-class"),
        pytest.param("apps.fire_brigade:Kind", "is not a subclass", id="a-class-not-a-strategy"),
        pytest.param("apps.fire_brigade:app", "is not a subclass", id="not-a-class"),
    ],
)
def test_strategy_class_refuses_what_is_not_a_strategy(name: str, message: str) -> None:
    with pytest.raises(ValueError, match=re.escape(message)):
        strategy_class(name)
