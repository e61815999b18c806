"""examples/operational --ros: one robot of a simulated swarm is a ROS 2 robot (a fake one).

The swarm of three simulated robots runs in this process on Zenoh; the fake
rmw_zenoh robot and the operational robot (``examples.operational.robot --ros``,
the same layer classes with RosDiffDrive as its middleware) are child processes.
The operational robot meets the swarm at the centroid of everyone's homes, driving
the fake robot there over /cmd_vel, and leaves.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import sys
from pathlib import Path

import pytest

pytest.importorskip("zenoh")
pytest.importorskip("rosbags")

from cas_async import ScaledClock, ZenohTransport
from cas_async.testing import peer_process
from examples.operational.layers import rendezvous
from examples.operational.network import NAMESPACE
from examples.operational.simulated import build_swarm, circle

from .helpers import free_port, until

ROOT = Path(__file__).resolve().parents[2]
FACTOR = 10.0
HOME = (8.0, 6.0)  # where the ROS robot's odom frame lies in the swarm's


@pytest.mark.slow
async def test_a_ros_robot_joins_the_simulated_swarm_through_the_same_layers() -> None:
    swarm_port, robot_endpoint = free_port(), f"tcp/127.0.0.1:{free_port()}"
    transport = ZenohTransport(namespace=NAMESPACE, listen=[f"tcp/127.0.0.1:{swarm_port}"])
    homes = circle(3, 5.0)
    centre = rendezvous((pose.x, pose.y) for pose in homes.values())
    together = rendezvous([*((pose.x, pose.y) for pose in homes.values()), HOME])
    simulated = build_swarm(homes, transport=transport, clock=ScaledClock(FACTOR))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    try:
        async with (
            simulated.swarm,
            peer_process(
                sys.executable,
                "-m",
                "cas_async.ros",
                "fake-robot",
                f"--listen={robot_endpoint}",
                f"--time-factor={FACTOR}",
                "--lifetime=60",
                ready="fake robot ready",
                timeout=30,
            ) as fake,
        ):
            await until(
                lambda: all(g.arrived for g in simulated.gathers.values()),
                "the simulated robots meet at their centre",
            )
            assert all(g.target == centre for g in simulated.gathers.values())
            robot = await asyncio.create_subprocess_exec(
                sys.executable,
                "-m",
                "examples.operational.robot",
                "--id=10",
                f"--x={HOME[0]}",
                f"--y={HOME[1]}",
                "--company=3",
                "--stay=1",
                f"--time-factor={FACTOR}",
                f"--connect=tcp/127.0.0.1:{swarm_port}",
                f"--ros={robot_endpoint}",
                cwd=ROOT,
                env=env,
                stdin=asyncio.subprocess.DEVNULL,
                stdout=asyncio.subprocess.PIPE,
                stderr=asyncio.subprocess.STDOUT,
            )
            try:
                async with asyncio.timeout(45):
                    out, _ = await robot.communicate()
            finally:
                if robot.returncode is None:
                    with contextlib.suppress(ProcessLookupError):
                        robot.kill()
                    await robot.wait()
            said = out.decode(errors="replace")
            assert robot.returncode == 0, said
            assert "drives the ROS 2 robot at" in said, said
            assert f"met robots [1, 2, 3] at ({together[0]:.3f}, {together[1]:.3f})" in said, said
            for g in simulated.gathers.values():
                assert g.joined == [10]
                assert g.homes.get(10) is None  # it left again
            fake.send_signal(2)  # SIGINT, as Ctrl-C
            assert fake.stdout is not None
            async with asyncio.timeout(15):
                rest = (await fake.stdout.read()).decode()
                status = await fake.wait()
            assert status == 0, rest
            assert "graph + NN /cas_robot_10" in rest
            assert "session closed: True" in rest
            x, y = (float(v) for v in rest.split("fake robot stopped at (")[1].split(",")[:2])
            # in its odom frame, which starts at HOME in the swarm's
            assert (x + HOME[0] - together[0]) ** 2 + (y + HOME[1] - together[1]) ** 2 < 0.1**2
    finally:
        transport.close()
    assert transport.session is None
