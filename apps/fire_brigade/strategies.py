"""The partner strategies a scenario can name: ``time``, ``random``, ``solo``, or a class path.

Each is a :class:`~.strategy.Strategy` that only overrides ``choose`` (thesis §5.7:
swapping the partner selection touches one function). The destination sink, when in
range, is always asked first by every strategy: handing it the bucket *is* delivering.
"""

from __future__ import annotations

import importlib
import random

from .base import Params
from .estimate import delivery_time, solo_time
from .messages import Kind
from .strategy import SearchView, Strategy

__all__ = ["STRATEGY_NAMES", "RandomStrategy", "SoloStrategy", "TimeStrategy", "strategy_class"]


class TimeStrategy(Strategy):
    """Time-optimal (§5.2, equations 1-5): the partner that gets the bucket to the sink soonest.

    A partner's score is the time for the two to meet plus the time the partner then
    needs to carry the bucket to the sink. A Transporter only asks partners that beat
    carrying the bucket itself; a Generator, which cannot carry it, asks everyone in range.
    """

    def choose(self, view: SearchView) -> list[int]:
        """Partners faster than carrying it oneself, fastest first (ties by id)."""
        sink = view.sink_in_range()
        if sink is not None:
            return [sink.robot]
        alone = (
            solo_time(view.here, view.carrying, view.sink_at)
            if view.carrying is not None
            else float("inf")
        )
        scored = []
        for candidate in view.candidates:
            t = delivery_time(
                view.here,
                view.carrying,
                candidate.at,
                view.fresh_partner,
                view.loaded_partner,
                view.sink_at,
            )
            if t < alone:
                scored.append((t, candidate.robot))
        return [robot for _, robot in sorted(scored)]


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


class SoloStrategy(TimeStrategy):
    """No collaboration (§5.8.2): a Transporter carries the bucket all the way to the sink.

    Generators still have to hand their buckets over; they choose as the time strategy does.
    """

    def choose(self, view: SearchView) -> list[int]:
        """A Transporter asks only the sink; a Generator asks as TimeStrategy."""
        if view.kind is Kind.GENERATOR:
            return super().choose(view)
        sink = view.sink_in_range()
        return [] if sink is None else [sink.robot]


_BUILT_IN: dict[str, type[Strategy]] = {
    "time": TimeStrategy,
    "random": RandomStrategy,
    "solo": SoloStrategy,
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
