"""The simulated-middleware tests' world: robot 1 at the origin, facing +x, on virtual time."""

from __future__ import annotations

from typing import TypeAlias

import pytest

from cas_async import Pose, VirtualClock
from cas_async.sim import Environment

Sim: TypeAlias = tuple[Environment, VirtualClock]
"""The world of a test marked ``cas_virtual``, and the clock its robots use."""


@pytest.fixture
def sim() -> Sim:
    """An Environment with robot 1 at the origin facing +x, and a virtual clock."""
    env = Environment()
    env.add_robot(1, Pose(0, 0, 0))
    return env, VirtualClock()
