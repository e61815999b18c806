"""The partner strategies a scenario can name, or a class path.

``time`` (the default, §5.2 as written), ``time_gain`` (the same, but a Transporter
hands over only when that gains time), ``sink_first`` (this demo's earlier time
rule), ``random`` (§5.7) and ``solo`` (§5.8.2). Each is a :class:`~.strategy.Strategy`
that only overrides ``choose`` (thesis §5.7: swapping the partner selection touches
one function).
"""

from __future__ import annotations

import importlib
import random

from .base import Params
from .estimate import delivery_time, solo_time
from .messages import Kind
from .strategy import SearchView, Strategy

__all__ = [
    "STRATEGY_NAMES",
    "RandomStrategy",
    "SinkFirstStrategy",
    "SoloStrategy",
    "TimeGainStrategy",
    "TimeStrategy",
    "strategy_class",
]


class TimeStrategy(Strategy):
    """Time-optimal, as §5.2 states it: every robot in range, ranked by the estimate.

    A candidate's score is the time for the two to meet plus the time the candidate
    then needs to carry the bucket to the sink (equations 1-5); the destination Sink,
    when in range, is a candidate like any other, scored by the time to reach it.
    The robot asks the best, on a refusal the next, and carries the bucket itself
    (one ``search_step``) only when nobody accepts; a Generator, which cannot carry,
    keeps asking. The one guard the thesis does not mention is the layer's: a bucket
    never goes straight back to the robot it came from (see :class:`Strategy`).
    """

    def choose(self, view: SearchView) -> list[int]:
        """Every candidate, soonest delivery first (ties by id)."""
        return [robot for _, robot in sorted(_scored(view))]


class TimeGainStrategy(Strategy):
    """The time rule with one guard: a Transporter hands over only when that gains time.

    Every robot in range, the Sink included, is ranked by the estimate as in
    :class:`TimeStrategy`, but a Transporter asks only the partners that would get
    the bucket to the Sink sooner than carrying it itself, and the Sink (which costs
    the same as carrying it there). A Generator, which cannot carry, asks everyone.
    This is the rule under which lines form in this model (see the README).
    """

    def choose(self, view: SearchView) -> list[int]:
        """Partners faster than carrying it oneself, and the sink, soonest first."""
        alone = _alone(view)
        return [robot for t, robot in sorted(_scored(view)) if t < alone or robot == view.sink]


class SinkFirstStrategy(Strategy):
    """The time rule as this demo had it before (kept for comparison).

    It departs from §5.2 twice: when the destination Sink is in range a carrier asks
    only the Sink, and a Transporter asks only partners that beat carrying the bucket
    itself (a Generator, which cannot carry it, asks everyone in range). Buckets go
    straight to the Sinks sooner, and the Transporters gather on the Sinks instead of
    forming lines.
    """

    def choose(self, view: SearchView) -> list[int]:
        """The sink if in range, else partners faster than carrying it oneself."""
        sink = view.sink_in_range()
        if sink is not None:
            return [sink.robot]
        alone = _alone(view)
        return [robot for t, robot in sorted(_scored(view)) if t < alone]


def _alone(view: SearchView) -> float:
    """The time for this robot to carry the bucket to the sink itself (inf: it cannot)."""
    if view.carrying is None:
        return float("inf")
    return solo_time(view.here, view.carrying, view.sink_at)


def _scored(view: SearchView) -> list[tuple[float, int]]:
    """``(estimated delivery time, robot)`` for every candidate of ``view``."""
    scored = []
    for candidate in view.candidates:
        if candidate.robot == view.sink:  # immobile: the bucket is there once they meet
            t = delivery_time(view.here, view.carrying, candidate.at, None, None, view.sink_at)
        else:
            t = delivery_time(
                view.here,
                view.carrying,
                candidate.at,
                view.fresh_partner,
                view.loaded_partner,
                view.sink_at,
            )
        scored.append((t, candidate.robot))
    return scored


class RandomStrategy(Strategy):
    """Random (§5.7): robots in range in a random order (the sink first when in range)."""

    def __init__(self, params: Params) -> None:
        super().__init__(params)
        self.rng = random.Random(params.seed)

    def choose(self, view: SearchView) -> list[int]:
        """The sink if in range, else every candidate, shuffled."""
        sink = view.sink_in_range()
        if sink is not None:
            return [sink.robot]
        robots = [candidate.robot for candidate in view.candidates]
        self.rng.shuffle(robots)
        return robots


class SoloStrategy(SinkFirstStrategy):
    """No collaboration (§5.8.2): a Transporter carries the bucket all the way to the sink.

    Generators still have to hand their buckets over; they choose as the time strategy does.
    """

    def choose(self, view: SearchView) -> list[int]:
        """A Transporter asks only the sink; a Generator asks as the time strategy."""
        if view.kind is Kind.GENERATOR:
            return super().choose(view)
        sink = view.sink_in_range()
        return [] if sink is None else [sink.robot]


_BUILT_IN: dict[str, type[Strategy]] = {
    "time": TimeStrategy,
    "random": RandomStrategy,
    "solo": SoloStrategy,
    "time_gain": TimeGainStrategy,
    "sink_first": SinkFirstStrategy,
}

STRATEGY_NAMES = tuple(_BUILT_IN)


def strategy_class(name: str) -> type[Strategy]:
    """The Strategy subclass named ``name``: a built-in name or ``"package.module:Class"``.

    Raises:
        ValueError: an unknown name, a path that does not import, or a class that is
            not a :class:`Strategy` subclass (the message says which).
    """
    if name in _BUILT_IN:
        return _BUILT_IN[name]
    module_name, sep, class_name = name.partition(":")
    if not sep or not module_name or not class_name:
        raise ValueError(
            f"expected one of {', '.join(STRATEGY_NAMES)} or 'package.module:Class', got {name!r}"
        )
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise ValueError(f"cannot import {module_name!r}: {exc}") from None
    found = getattr(module, class_name, None)
    if not (isinstance(found, type) and issubclass(found, Strategy)):
        raise ValueError(f"{name!r} is not a subclass of apps.fire_brigade.Strategy")
    if found.choose is Strategy.choose:
        raise ValueError(f"{name!r} does not implement choose()")
    return found
