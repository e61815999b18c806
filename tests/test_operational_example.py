"""examples/operational: a robot alone in its process joins a simulated swarm over Zenoh.

The swarm runs here (three simulated robots, one ZenohTransport listening on a free
loopback port); the operational robot is a real child process
(``python -m examples.operational.robot``) with a stub driver instead of the
simulator. Both sides run the same layer classes. The stub driver, and the same
meeting in one process on virtual time, are checked first.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import os
import re
import socket
import sys
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import pytest

from cas_async import (
    ConstantSpeed,
    MemoryTransport,
    Pose,
    Robot,
    ScaledClock,
    VirtualClock,
    ZenohTransport,
)
from examples.operational.driver import StubDriver
from examples.operational.layers import Drive, Gather, Point, rendezvous
from examples.operational.messages import MESSAGES
from examples.operational.network import NAMESPACE
from examples.operational.simulated import build_swarm, circle

pytestmark = pytest.mark.slow  # a robot in another process

ROOT = Path(__file__).resolve().parent.parent
TIME_FACTOR = 10.0  # simulated seconds per wall second, in both processes
CHILD = 10
CHILD_HOME: Point = (8.0, 6.0)
WAIT = 8.0  # wall seconds any one step may take at most
MOVE = re.compile(rf"robot {CHILD} driver: move_to\((\S+), (\S+)\)")


def free_port() -> int:
    """A TCP port on 127.0.0.1 nobody listens on now (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


def near(a: Point | None, b: Point) -> bool:
    return a is not None and math.dist(a, b) < 1e-9


def xyh(pose: Pose) -> tuple[float, float, float]:
    """A pose as a tuple, for ``pytest.approx``."""
    return pose.x, pose.y, pose.heading


async def until(condition: Callable[[], bool], what: str, timeout: float = WAIT) -> None:
    """Waits (polling: real datagrams travel between processes) until ``condition()``."""
    try:
        async with asyncio.timeout(timeout):
            while not condition():
                await asyncio.sleep(0.01)
    except TimeoutError:
        raise AssertionError(f"not within {timeout:g} s: {what}") from None


class Child:
    """A child process whose output (stdout and stderr, merged) is read line by line."""

    def __init__(self, process: asyncio.subprocess.Process) -> None:
        self.process = process
        self.lines: list[str] = []
        self.reader = asyncio.ensure_future(self._read())

    async def _read(self) -> None:
        stream = self.process.stdout
        if stream is None:  # pragma: no cover - a pipe was asked for
            return
        while line := await stream.readline():
            self.lines.append(line.decode(errors="replace").rstrip())

    def said(self) -> str:
        return "\n".join(self.lines)


@contextlib.asynccontextmanager
async def operational_robot(*argv: str) -> AsyncIterator[Child]:
    """Starts the operational robot; on the way out kills it if it still runs, and reaps it."""
    process = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "examples.operational.robot",
        *argv,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdin=asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
    )
    child = Child(process)
    try:
        yield child
    finally:
        if process.returncode is None:
            with contextlib.suppress(ProcessLookupError):  # it may have just ended
                process.kill()
        try:
            async with asyncio.timeout(5.0):
                await asyncio.gather(process.wait(), child.reader)
        finally:
            child.reader.cancel()


@pytest.mark.cas_virtual
async def test_the_stub_driver_logs_each_command_and_dead_reckons_its_pose(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger="examples.operational.driver")
    clock = VirtualClock()
    clock.start()
    driver = StubDriver(
        7, Pose(0.0, 0.0), clock, speed_profile=ConstantSpeed(2.0), turn_rate=math.pi / 2
    )
    move = asyncio.ensure_future(driver.move_to(0.0, 4.0))  # turn 1 s, then drive 2 s
    await clock.sleep_until(0.5)
    assert driver.pose() == Pose(0.0, 0.0, math.pi / 4)  # half-way through the turn
    await clock.sleep_until(2.0)
    assert xyh(driver.pose()) == pytest.approx((0.0, 2.0, math.pi / 2))  # 1 s of driving
    assert await move == Pose(0.0, 4.0, math.pi / 2)
    assert clock.now() == 3.0
    assert await driver.rotate_to(math.pi) == Pose(0.0, 4.0, math.pi)
    assert clock.now() == 4.0
    move = asyncio.ensure_future(driver.move_to(-4.0, 4.0))  # no turn: 2 s of driving
    await clock.sleep_until(5.0)
    move.cancel()  # stops where it is
    with pytest.raises(asyncio.CancelledError):
        await move
    assert xyh(driver.pose()) == pytest.approx((-2.0, 4.0, math.pi))
    assert caplog.messages == [
        "robot 7 driver: move_to(0.000000, 4.000000) from (0.000, 0.000): 4.000 m",
        "robot 7 driver: at (0.000, 4.000)",
        "robot 7 driver: rotate_to(3.141593)",
        "robot 7 driver: at (0.000, 4.000)",
        "robot 7 driver: move_to(-4.000000, 4.000000) from (0.000, 4.000): 4.000 m",
        "robot 7 driver: stopped at (-2.000, 4.000)",
    ]


@pytest.mark.cas_virtual
async def test_the_same_layers_meet_with_a_stub_driver_among_simulated_robots() -> None:
    # One process, virtual time, in-memory transport: the quick twin of the Zenoh test.
    transport, clock = MemoryTransport(), VirtualClock()
    homes = circle(3, 5.0)
    centre = rendezvous((pose.x, pose.y) for pose in homes.values())
    together = rendezvous([*((pose.x, pose.y) for pose in homes.values()), CHILD_HOME])
    simulated = build_swarm(homes, transport=transport, clock=clock)
    driver = StubDriver(CHILD, Pose(*CHILD_HOME), clock, speed_profile=ConstantSpeed(1.0))
    gather = Gather(company=3, stay=1.0)
    visitor = Robot(
        CHILD, [gather, Drive(driver)], transport=transport, clock=clock, messages=MESSAGES
    )
    gathers = simulated.gathers.values()
    async with simulated.swarm:
        await clock.sleep(10.0)  # they meet at their centre first
        assert all(g.arrived and near(g.target, centre) for g in gathers)
        async with asyncio.timeout(60.0):  # simulated seconds: the loop jumps over idle time
            async with visitor:
                await visitor.run()  # until it has met them, and stayed
        assert gather.met == (1, 2, 3)
        assert driver.pose().distance_to(*together) == pytest.approx(0.0, abs=1e-9)
        for robot_id, g in simulated.gathers.items():
            where = simulated.environment.pose_at(robot_id, clock.now())
            assert where.distance_to(*together) == pytest.approx(0.0, abs=1e-9)
            assert g.joined == [CHILD]
        await clock.sleep(10.0)  # it left: they go back to their centre
        assert all(g.left == [CHILD] for g in gathers)
        assert all(g.arrived and near(g.target, centre) for g in gathers)


async def test_an_operational_robot_joins_meets_the_swarm_and_leaves(
    caplog: pytest.LogCaptureFixture,
) -> None:
    pytest.importorskip("zenoh")
    caplog.set_level(logging.DEBUG, logger="cas_async.layer")
    port = free_port()
    transport = ZenohTransport(namespace=NAMESPACE, listen=[f"tcp/127.0.0.1:{port}"])
    homes = circle(3, 5.0)
    centre = rendezvous((pose.x, pose.y) for pose in homes.values())
    together = rendezvous([*((pose.x, pose.y) for pose in homes.values()), CHILD_HOME])
    simulated = build_swarm(homes, transport=transport, clock=ScaledClock(TIME_FACTOR))
    gathers = simulated.gathers.values()
    try:
        async with simulated.swarm:
            await until(
                lambda: all(g.arrived and near(g.target, centre) for g in gathers),
                "the simulated robots meet at their centre",
            )
            async with operational_robot(
                f"--id={CHILD}",
                f"--x={CHILD_HOME[0]}",
                f"--y={CHILD_HOME[1]}",
                "--company=3",
                "--stay=1",
                f"--time-factor={TIME_FACTOR}",
                f"--connect=tcp/127.0.0.1:{port}",
            ) as child:
                # It joins: every simulated robot's layer hears of it and can reach it.
                await until(
                    lambda: all(CHILD in g.joined and g.knows(CHILD) for g in gathers),
                    f"the swarm sees robot {CHILD} join\n{child.said()}",
                )
                # Introduce/Home, a request and its reply across processes: each side
                # learns where the other started, and they agree on a new point.
                await until(
                    lambda: all(g.homes.get(CHILD) == CHILD_HOME for g in gathers),
                    f"robot {CHILD} introduced to the swarm\n{child.said()}",
                )
                # It meets the three simulated robots there, then leaves by itself.
                async with asyncio.timeout(WAIT):
                    status = await child.process.wait()
                    await child.reader
                said = child.said()
                assert status == 0, said
                moves = [(float(x), float(y)) for x, y in MOVE.findall(said)]
                assert moves, f"the stub driver logged no move_to:\n{said}"
                assert moves[-1] == pytest.approx(together, abs=1e-6), said
                assert f"met robots [1, 2, 3] at ({together[0]:.3f}, {together[1]:.3f})" in said
            # The simulated robots drove there too, and were told it had arrived...
            told = f"robot {CHILD} is at ({together[0]:.3f}, {together[1]:.3f})"
            for robot_id, g in simulated.gathers.items():
                assert any(near(plan, together) for plan in g.plans)
                assert f"robot {robot_id} Gather(L0): {told}" in caplog.messages
            # ... and see it leave, and go back to their own centre.
            await until(
                lambda: all(CHILD in g.left and not g.knows(CHILD) for g in gathers),
                f"the swarm sees robot {CHILD} leave",
            )
            await until(
                lambda: all(g.arrived and near(g.target, centre) for g in gathers),
                "the simulated robots meet at their centre again",
            )
            assert all(CHILD not in g.homes for g in gathers)
            assert transport.sent > 0
            assert transport.received > 0
            assert transport.dropped == {}
    finally:
        transport.close()  # idempotent: the swarm closed it already unless it failed to start
    assert transport.session is None
