"""What the latency tests of the Environment share: a world on virtual time, seen and checked."""

from __future__ import annotations

import math

from cas_async import ConstantSpeed, Pose, VirtualClock
from cas_async.sim import Environment, ItemEventKind, ItemLedger, Motion

L = 0.5
SENT, TRANSFERRED, REFUSED, RETURNED, CREATED = (
    ItemEventKind.SENT,
    ItemEventKind.TRANSFERRED,
    ItemEventKind.REFUSED,
    ItemEventKind.RETURNED,
    ItemEventKind.CREATED,
)


def started_clock() -> VirtualClock:
    """A virtual clock started now, at loop time 0 (a test marked ``cas_virtual``)."""
    clock = VirtualClock()
    clock.start()
    assert clock.now() == 0.0
    return clock


def world(clock: VirtualClock, *poses: tuple[float, float], **kwargs: float) -> Environment:
    """An Environment with latency ``L``, robots 1, 2... at ``poses``, its ledger always checked."""
    env = Environment(latency=L, clock=clock, **kwargs)
    for robot_id, (x, y) in enumerate(poses, start=1):
        env.add_robot(robot_id, Pose(x, y, 0.0))
    checked(env.items)
    return env


def checked(ledger: ItemLedger) -> None:
    """The full invariant after every event of ``ledger``."""
    ledger.subscribe(lambda _event: ledger.check())


def drive(env: Environment, robot_id: int, t: float, x: float, y: float) -> Motion:
    """Starts robot ``robot_id`` towards ``(x, y)`` at ``t``, 1 unit/s, turning at once."""
    here = env.pose_at(robot_id, t)
    motion = Motion.straight_to(here, x, y, turn_rate=math.inf, profile=ConstantSpeed(1.0))
    env.start_motion(robot_id, motion, t)
    return motion


async def until(clock: VirtualClock, t: float) -> None:
    """Waits for simulated instant ``t``, exactly."""
    await clock.sleep_until(t)
    assert clock.now() == t


def seen(env: Environment, asker: int, t: float) -> dict[int, tuple[float, float]]:
    """Where ``asker`` sees every other robot at ``t``."""
    return env.within(asker, math.inf, t).as_dict()


def story(ledger: ItemLedger) -> list[tuple[float, ItemEventKind, int]]:
    """Every event of ``ledger``: when, what, in whose hands."""
    return [(event.t, event.kind, event.actor) for event in ledger.events]
