"""``LearnedStrategy``: the Fire Brigade's Strategy layer, its partner choice made by a policy."""

from __future__ import annotations

from dataclasses import dataclass

from apps.fire_brigade import SearchView, TimeStrategy
from apps.fire_brigade.base import Params
from apps.fire_brigade.estimate import delivery_time, solo_time
from cas_async.rl import PolicyLayer

__all__ = ["Choice", "LearnedStrategy"]


@dataclass(frozen=True, slots=True)
class Choice:
    """A partner search, as the policy's ``act`` and ``observe`` see it.

    Attributes:
        view: what the Strategy layer knows: where it is, its sink, the robots in range.
        ranked: the candidates, soonest estimated delivery first (the time
            strategy's order, thesis §5.2, equations 1-5).
        times: each ranked candidate's estimated delivery time, in seconds.
        alone: how long this robot would take to carry the bucket itself
            (``inf`` for a Generator, which cannot).
    """

    view: SearchView
    ranked: tuple[int, ...]
    times: tuple[float, ...]
    alone: float


class LearnedStrategy(PolicyLayer, TimeStrategy):
    """The time strategy, whose list of robots to ask comes from the env's ``act``.

    Everything else is the app's Strategy layer: the search for robots in range,
    asking them in turn, carrying a step when nobody accepts (a Generator waits and
    looks farther), answering other robots' requests.

    Attributes:
        last_choice: the latest search, ``None`` before the first.
    """

    def __init__(self, params: Params) -> None:
        super().__init__(params)
        self.last_choice: Choice | None = None

    def choose(self, view: SearchView) -> list[int]:
        """The robots to ask, in order: what ``act`` makes of the action held now."""
        ranked = tuple(super().choose(view))  # soonest estimated delivery first
        at = {candidate.robot: candidate.at for candidate in view.candidates}
        times = tuple(self._estimate(view, at[robot], robot == view.sink) for robot in ranked)
        alone = (
            float("inf")
            if view.carrying is None
            else solo_time(view.here, view.carrying, view.sink_at)
        )
        choice = Choice(view, ranked, times, alone)
        self.last_choice = choice  # what observe() reads
        return list(self.decide(choice))  # act(layer, action, choice)

    @staticmethod
    def _estimate(view: SearchView, at: tuple[float, float], is_sink: bool) -> float:
        if is_sink:  # immobile: the bucket is there once they meet
            return delivery_time(view.here, view.carrying, at, None, None, view.sink_at)
        return delivery_time(
            view.here, view.carrying, at, view.fresh_partner, view.loaded_partner, view.sink_at
        )
