"""End to end: a fake rmw_zenoh robot in its own process, found, driven, and gone after.

``python -m cas_async.ros fake-robot`` runs a Zenoh router configured like
``rmw_zenohd`` and, behind it, the robot's node in a peer session (as rmw_zenoh's
nodes are): it integrates unicycle kinematics from ``/cmd_vel`` and publishes
``/odom``. This test, a foreign session, connects as a client to its router,
discovers the robot from its tokens, drives it with RosDiffDrive to three goals on
odometry alone, and reads the robot's own view of the graph (each token parsed as
rmw_zenoh's graph cache parses it, printed by the robot). Afterwards the robot
sees our tokens go, is stopped with SIGTERM, says its session closed, and exits 0.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
import sys
import time

import pytest

pytest.importorskip("zenoh")
pytest.importorskip("rosbags")

from cas_async import ConstantSpeed, ScaledClock
from cas_async.ros import RosDiffDrive, RosLink
from cas_async.testing import peer_process

from .helpers import PATIENT, free_port, until

FACTOR = 4.0  # simulated seconds per wall second, robot and middleware alike
GOALS = [(1.5, 0.0), (1.5, 1.5), (0.0, 0.5)]
TWIST = (
    "geometry_msgs::msg::dds_::Twist_ "
    "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
)
ODOMETRY = (
    "nav_msgs::msg::dds_::Odometry_ "
    "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"
)
OURS = [
    "NN /cas_robot_10",
    f"MP /cmd_vel {TWIST} ::,10:,:,:,, /cas_robot_10",
    f"MS /odom {ODOMETRY} ::,10:,:,:,, /cas_robot_10",
]


@pytest.mark.slow
async def test_a_fake_rmw_zenoh_robot_is_found_driven_to_three_goals_and_all_ends() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    lines: list[str] = []
    link = RosLink("cas_robot_10", connect=endpoint)
    async with peer_process(
        sys.executable,
        "-m",
        "cas_async.ros",
        "fake-robot",
        f"--listen={endpoint}",
        f"--time-factor={FACTOR}",
        "--lifetime=60",
        ready="fake robot ready",
        timeout=30,
    ) as process:
        assert process.stdout is not None
        stdout = process.stdout

        async def read() -> None:
            while line := await stdout.readline():
                lines.append(line.decode().rstrip())

        reader = asyncio.ensure_future(read())
        try:
            began = time.monotonic()
            async with link:
                drive = RosDiffDrive(
                    link,
                    10,
                    ScaledClock(FACTOR),
                    speed_profile=ConstantSpeed(0.8),
                    **PATIENT,  # a loaded machine's wall time (see helpers.PATIENT)
                )
                async with drive:
                    discovered = time.monotonic() - began
                    # It is discovered from its tokens: a node with /cmd_vel and /odom.
                    assert "/fake_robot" in link.nodes()
                    assert [e.node_fqn for e in link.endpoints("cmd_vel", "MS")] == ["/fake_robot"]
                    assert [e.node_fqn for e in link.endpoints("odom", "MP")] == ["/fake_robot"]
                    tolerance = 0.05
                    for x, y in GOALS:
                        reached = await drive.move_to(x, y)
                        assert reached.distance_to(x, y) <= tolerance, (x, y, reached)
                        # odometry back: the pose it reports now is where it stopped
                        assert drive.pose().distance_to(x, y) <= tolerance + 0.02
                # The robot's graph cache parsed our node and both our endpoints.
                await until(
                    lambda: all(f"graph + {entity}" in lines for entity in OURS),
                    "the robot sees our node and endpoints\n" + "\n".join(lines),
                )
            assert link.session is None
            await until(
                lambda: all(f"graph - {entity}" in lines for entity in OURS),
                "the robot sees our tokens go\n" + "\n".join(lines),
            )
            process.send_signal(signal.SIGTERM)
            async with asyncio.timeout(15):
                status = await process.wait()
                await reader
        finally:
            reader.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await reader
    said = "\n".join(lines)
    assert status == 0, said
    summary = lines[-1]
    assert summary.startswith("fake robot stopped at"), said
    assert "dropped {}" in summary, said
    assert "tokens refused 0" in summary, said
    assert "session closed: True" in summary, said
    received = int(summary.split("cmd_vel received ")[1].split(",")[0])
    assert received > len(GOALS), said
    assert process.returncode == 0
    assert discovered < 15, f"discovery took {discovered:.1f} s"
