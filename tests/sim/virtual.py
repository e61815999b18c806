"""Running a simulation on virtual time, for the simulated-middleware tests."""

from __future__ import annotations

from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

import cas_async
from cas_async import Pose, VirtualClock
from cas_async.sim import Environment

T = TypeVar("T")


def virtual(main: Callable[[Environment, VirtualClock], Coroutine[Any, Any, T]]) -> T:
    """Runs ``main(env, clock)`` on virtual time, with robot 1 at the origin facing +x."""
    env, clock = Environment(), VirtualClock()
    env.add_robot(1, Pose(0, 0, 0))
    return cas_async.run(main(env, clock), virtual=True)
