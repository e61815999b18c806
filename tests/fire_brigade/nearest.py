"""A partner strategy defined outside the app, named in a scenario by its import path.

``strategy.name = "tests.fire_brigade.nearest:NearestFirst"`` loads it: the CLI
tests check that a user's own Strategy subclass runs end to end.
"""

from __future__ import annotations

import math

from apps.fire_brigade import SearchView, Strategy

__all__ = ["NearestFirst"]


class NearestFirst(Strategy):
    """The destination sink when in range, else every robot in range, nearest first."""

    def choose(self, view: SearchView) -> list[int]:
        """The sink alone when in range; otherwise candidates by distance (ties by id)."""
        sink = view.sink_in_range()
        if sink is not None:
            return [sink.robot]
        here_x, here_y = view.here
        ranked = sorted(
            view.candidates,
            key=lambda c: (math.hypot(c.at[0] - here_x, c.at[1] - here_y), c.robot),
        )
        return [candidate.robot for candidate in ranked]
