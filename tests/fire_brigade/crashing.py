"""A Strategy that raises once per robot, to test failures and restarts of whole runs."""

from __future__ import annotations

from apps.fire_brigade.strategies import TimeStrategy
from apps.fire_brigade.strategy import SearchView


class CrashOnce(TimeStrategy):
    """The time strategy, except that each robot's first ranking after 2 s raises."""

    crashed = False

    def choose(self, view: SearchView) -> list[int]:
        if not self.crashed and self.clock.now() > 2.0:
            self.crashed = True
            raise RuntimeError(f"robot {self.robot_id}: the strategy broke down")
        return super().choose(view)
