"""A second balancing rule, to swap in from a scenario file: fixed sides.

::

    [layers]
    coordination = "apps.box_moving.coordination_fixed.FixedSideCoordination"

The pair always lifts along the west-east axis, the lower id at the west side,
whatever the robots' positions: simple to predict, and measurably worse than
the default rule (robots walk round the object to reach their side), which is
what the scenario ``thesis_4_4_fixed.toml`` shows.
"""

from __future__ import annotations

from .coordination import Coordination
from .geometry import Point
from .messages import Side, Sighting

__all__ = ["FixedSideCoordination"]


class FixedSideCoordination(Coordination):
    """Coordination whose balancing rule puts the lower id at the west side."""

    def choose_sides(
        self, leader: int, leader_at: Point, helper: int, helper_at: Point, box: Sighting
    ) -> tuple[Side, Side]:
        """West for the lower id, east for the other."""
        del leader_at, helper_at, box  # the rule ignores where anything is
        if leader < helper:
            return Side.WEST, Side.EAST
        return Side.EAST, Side.WEST
