"""What happens when a layer raises: the robot stops, or the layer is restarted.

By default a failure is final: the failing layer's exception is logged with its
traceback, the robot's other layers are cancelled at once (no simulated time
passes), and ``robot.run()`` raises :class:`~cas_async._errors.LayerError` naming
the robot and the layer, with the original exception as ``__cause__``.

With a :class:`RestartPolicy` the failed layer runs again instead, as an Erlang
supervisor would restart a worker: its ``on_restart(error)`` hook resets what
the failure left half done, then ``inner_process()`` and the message loop start
over. Messages already waiting for the layer are kept; the message being handled
when it failed is not handled again. When failures come faster than the policy
allows, the robot stops as without a policy.
"""

from __future__ import annotations

import asyncio
import math
from collections import deque
from dataclasses import dataclass

from .._errors import LayerError
from ._layer_runtime import LayerRuntime

__all__ = ["RestartPolicy", "run_layer"]


@dataclass(frozen=True, slots=True)
class RestartPolicy:
    """Restart a failed layer, up to ``max_restarts`` times within ``within`` simulated seconds.

    Attributes:
        max_restarts: restarts allowed inside any window of ``within`` seconds; one
            more failure in that window stops the robot.
        within: the window, in simulated seconds (``math.inf``: over the robot's life).
    """

    max_restarts: int = 3
    within: float = 60.0

    def __post_init__(self) -> None:
        if type(self.max_restarts) is not int or self.max_restarts < 0:
            raise ValueError(f"max_restarts must be an int >= 0, got {self.max_restarts!r}")
        if not self.within > 0:
            raise ValueError(f"within must be > 0 simulated seconds, got {self.within!r}")


async def run_layer(runtime: LayerRuntime, policy: RestartPolicy | None) -> None:
    """Runs a layer's loop under ``policy`` until the robot cancels it.

    Raises:
        LayerError: the layer failed (and may not be restarted).
    """
    failures: deque[float] = deque()
    robot_id, level, name, log = runtime.robot.robot_id, runtime.level, runtime.name, runtime.log
    while True:
        try:
            await runtime.run_loop()
            return
        except asyncio.CancelledError as exc:
            task = asyncio.current_task()
            if task is not None and task.cancelling():
                raise  # the robot is stopping (or a sibling failed)
            # Nobody cancelled this task: an await inside the layer was cancelled (say,
            # a driver's future). The layer is dead; the robot must not run on without it.
            log.error("failed: an await was cancelled from outside the robot")
            raise LayerError(robot_id, level, name, exc) from exc
        except Exception as exc:
            if policy is None or not _may_restart(runtime.clock.now(), policy, failures):
                log.error("failed, stopping the robot", exc_info=exc)
                raise LayerError(robot_id, level, name, exc) from exc
            log.error(
                "failed, restarting (restart %d of %d allowed within %g s)",
                len(failures),
                policy.max_restarts,
                policy.within,
                exc_info=exc,
            )
            runtime.counters.restarts += 1
            try:
                await runtime.layer.on_restart(exc)
            except Exception as again:
                log.error("on_restart failed, stopping the robot", exc_info=again)
                raise LayerError(robot_id, level, name, again) from again


def _may_restart(now: float, policy: RestartPolicy, failures: deque[float]) -> bool:
    """Records a failure at ``now``; whether the policy still allows a restart."""
    failures.append(now)
    if policy.within != math.inf:
        while failures and failures[0] <= now - policy.within:
            failures.popleft()
    return len(failures) <= policy.max_restarts
