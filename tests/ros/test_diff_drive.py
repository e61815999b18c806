"""RosDiffDrive against a FakeRobot in this process: driving, frames, refusals, time-outs.

The robot and the middleware share a time factor (4 simulated seconds per wall
second), so a move of a few metres takes about a wall second. The end-to-end
test (test_end_to_end.py) runs the robot in its own process.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

import pytest

pytest.importorskip("zenoh")
pytest.importorskip("rosbags")

from cas_async import ConfigurationError, ConstantSpeed, Pose, RobotStateError, ScaledClock
from cas_async.ros import FakeRobot, RosDiffDrive, RosLink, RosTimeout, RosTypeMismatchWarning

from .helpers import PATIENT, free_port, until, zenoh_session

FACTOR = 4.0
STAMPED = "geometry_msgs/msg/TwistStamped"
Started = tuple[FakeRobot, asyncio.Event]


@pytest.fixture
async def fake_robot() -> AsyncIterator[Callable[..., Awaitable[Started]]]:
    """Starts FakeRobots on free ports; stops, closes and checks them after the test."""
    running: list[tuple[FakeRobot, asyncio.Event, asyncio.Future[None]]] = []

    async def start(**kwargs: Any) -> Started:
        robot = FakeRobot(listen=f"tcp/127.0.0.1:{free_port()}", time_factor=FACTOR, **kwargs)
        await robot.__aenter__()
        stop = asyncio.Event()
        running.append((robot, stop, asyncio.ensure_future(robot.run(stop))))
        return robot, stop

    try:
        yield start
    finally:
        for robot, stop, task in running:
            stop.set()
            try:
                async with asyncio.timeout(5):
                    await task
            finally:
                robot.close()
            assert robot.link.session is None


@pytest.fixture
async def link_to() -> AsyncIterator[Callable[[FakeRobot], Awaitable[RosLink]]]:
    links: list[RosLink] = []

    async def connect(robot: FakeRobot) -> RosLink:
        link = RosLink("cas_robot", connect=robot.listen)
        links.append(link)
        await link.open()
        return link

    try:
        yield connect
    finally:
        for link in links:
            link.close()
            assert link.session is None


def drive_of(link: RosLink, **kwargs: Any) -> RosDiffDrive:
    kwargs.setdefault("speed_profile", ConstantSpeed(0.8))
    return RosDiffDrive(link, 7, ScaledClock(FACTOR), **{**PATIENT, **kwargs})


@pytest.mark.slow  # a few seconds: the fast suite stays under 2 minutes
async def test_it_drives_to_a_goal_in_the_layers_frame_and_turns(
    fake_robot: Callable[..., Awaitable[Started]],
    link_to: Callable[[FakeRobot], Awaitable[RosLink]],
) -> None:
    robot, _ = await fake_robot()
    link = await link_to(robot)
    origin = Pose(8.0, 6.0, math.pi / 2)  # the odom frame's origin, in the layers' frame
    async with drive_of(link, origin=origin) as drive:
        assert drive.pose() == origin
        tolerance = 0.05
        reached = await drive.move_to(8.0, 8.0)  # 2 m straight ahead (odom +x)
        assert reached.distance_to(8.0, 8.0) <= tolerance
        assert robot.pose.distance_to(2.0, 0.0) <= tolerance + 0.02  # in its own odom frame
        reached = await drive.rotate_to(0.0)
        assert abs(math.remainder(reached.heading, math.tau)) <= 0.03
        assert drive.speed_profile == ConstantSpeed(0.8)
        assert len(await drive.robots_within(100.0)) == 0
    await until(lambda: robot.velocity == (0.0, 0.0), "the robot is told to stop at the end")


@pytest.mark.slow
async def test_a_robot_that_wants_twist_stamped_is_refused_saying_what_to_pass(
    fake_robot: Callable[..., Awaitable[Started]],
    link_to: Callable[[FakeRobot], Awaitable[RosLink]],
) -> None:
    robot, _ = await fake_robot(cmd_vel_type=STAMPED)
    link = await link_to(robot)
    drive = drive_of(link)
    with (
        pytest.warns(RosTypeMismatchWarning, match="TwistStamped_"),
        pytest.raises(ConfigurationError, match=rf"pass cmd_vel_type='{STAMPED}'"),
    ):
        await drive.start()
    async with drive_of(link, cmd_vel_type=STAMPED) as stamped:
        reached = await stamped.move_to(-1.0, 0.5)
        assert reached.distance_to(-1.0, 0.5) <= 0.05


async def test_no_robot_behind_the_router_times_out_naming_the_topic() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    async with zenoh_session("router", endpoint), RosLink(connect=endpoint) as link:
        with pytest.raises(RosTimeout, match=r"no ROS node subscribes to /cmd_vel"):
            await drive_of(link, discovery_timeout=1.0).start()
        assert link.endpoints("cmd_vel") == []


async def test_odometry_that_stops_fails_the_move_and_the_robot_is_told_to_stop(
    fake_robot: Callable[..., Awaitable[Started]],
    link_to: Callable[[FakeRobot], Awaitable[RosLink]],
) -> None:
    robot, stop = await fake_robot()
    link = await link_to(robot)
    async with drive_of(link, odom_timeout=1.0) as drive:
        stop.set()  # the robot's driver stops publishing
        await asyncio.sleep(0.1)
        with pytest.raises(RosTimeout, match=r"no odometry on /odom for 1 s \(move_to"):
            await drive.move_to(3.0, 0.0)
        assert drive.pose() == Pose(0.0, 0.0)  # the last odometry it had


async def test_a_move_that_takes_too_long_times_out_and_moves_are_exclusive(
    fake_robot: Callable[..., Awaitable[Started]],
    link_to: Callable[[FakeRobot], Awaitable[RosLink]],
) -> None:
    robot, _ = await fake_robot(max_speed=0.1)  # far slower than the profile asks
    link = await link_to(robot)
    async with drive_of(link, move_timeout=1.0) as drive:
        with pytest.raises(RosTimeout, match=r"move_to\(5.000, 0.000\) not done within 1.0 s"):
            await drive.move_to(5.0, 0.0)
    async with drive_of(link) as drive:
        move = asyncio.ensure_future(drive.move_to(5.0, 0.0))
        await until(lambda: robot.velocity[0] > 0, "it drives")
        with pytest.raises(RobotStateError, match="already moving"):
            await drive.rotate_to(1.0)
        move.cancel()
        with pytest.raises(asyncio.CancelledError):
            await move
        await until(lambda: robot.velocity == (0.0, 0.0), "a cancelled move stops the robot")
        assert 0.0 < drive.pose().x < 5.0


async def test_bad_settings_are_refused(
    fake_robot: Callable[..., Awaitable[Started]],
    link_to: Callable[[FakeRobot], Awaitable[RosLink]],
) -> None:
    robot, _ = await fake_robot()
    link = await link_to(robot)
    with pytest.raises(ConfigurationError, match="cmd_vel_type must be"):
        drive_of(link, cmd_vel_type="geometry_msgs/msg/Pose")
    with pytest.raises(ConfigurationError, match="odom_timeout must be > 0"):
        drive_of(link, odom_timeout=0)
    drive = drive_of(link)
    with pytest.raises(RobotStateError, match="no odometry yet"):
        drive.pose()
    with pytest.raises(RobotStateError, match="start RosDiffDrive"):
        await drive.move_to(1.0, 1.0)
