"""A layer that raises: the robot stops at once, or the layer is restarted under a policy."""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import math

import pytest

import cas_async
from cas_async import (
    Layer,
    LayerError,
    Message,
    RestartPolicy,
    Robot,
    RobotState,
    ScaledClock,
    VirtualClock,
)
from cas_async.testing import wait_all_tasks_blocked
from tests.stacks import STACK_MESSAGES, Note


class Failing(Layer):
    """Fails ``failures`` times, each ``after`` simulated seconds into a run of inner_process."""

    def __init__(self, after: float, failures: int = 1_000_000) -> None:
        self.after = after
        self.failures = failures
        self.runs: list[float] = []
        self.errors: list[Exception] = []  # raised, in order
        self.restarted_with: list[tuple[float, Exception]] = []
        self.done = False

    async def inner_process(self) -> None:
        if self.done:
            return
        self.runs.append(self.clock.now())
        await self.clock.sleep(self.after)
        if len(self.errors) < self.failures:
            error = RuntimeError(f"failure {len(self.errors) + 1}")
            self.errors.append(error)
            raise error
        self.done = True

    async def on_restart(self, error: Exception) -> None:
        self.restarted_with.append((self.clock.now(), error))

    def termination_condition(self) -> bool:
        return self.done


class Sleeper(Layer):
    """Sleeps a simulated hour in inner_process; notes when it is cancelled."""

    def __init__(self) -> None:
        self.cancelled_at: float | None = None

    async def inner_process(self) -> None:
        try:
            await self.clock.sleep(3600.0)
        except asyncio.CancelledError:
            self.cancelled_at = self.clock.now()
            raise


def run_robot(
    layers: list[Layer], restart: RestartPolicy | None
) -> tuple[Robot, BaseException | None, float]:
    """Runs a robot on virtual time; its error (if any) and the simulated time it ended."""

    async def main() -> tuple[Robot, BaseException | None, float]:
        clock = VirtualClock()
        robot = Robot(3, layers, clock=clock, messages=STACK_MESSAGES, restart=restart)
        try:
            async with robot:
                async with asyncio.timeout(100_000):  # virtual: a hang fails, not hangs
                    await robot.run()
        except LayerError as error:
            return robot, error, clock.now()
        return robot, None, clock.now()

    return cas_async.run(main(), virtual=True)


# -- without a policy ----------------------------------------------------------------------


def test_without_a_policy_a_failure_stops_the_robot_at_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    failing, sleeper = Failing(after=5.0), Sleeper()
    with caplog.at_level(logging.ERROR, logger="cas_async"):
        robot, error, end = run_robot([failing, sleeper], restart=None)
    assert isinstance(error, LayerError)
    assert end == 5.0  # no simulated time passed between the failure and run() raising
    assert str(error) == "robot 3, layer 0 (Failing) failed: RuntimeError: failure 1"
    assert (error.robot_id, error.level, error.layer_name) == (3, 0, "Failing")
    assert error.__cause__ is failing.errors[0]
    assert sleeper.cancelled_at == 5.0
    assert failing.runs == [0.0]
    assert failing.restarted_with == []
    assert failing.counters.restarts == 0
    assert robot.state is RobotState.STOPPED
    (record,) = [r for r in caplog.records if r.name == "cas_async.layer"]
    assert record.levelno == logging.ERROR
    assert record.getMessage() == "robot 3 Failing(L0): failed, stopping the robot"
    assert record.exc_info is not None
    assert record.exc_info[1] is failing.errors[0]


def test_a_zero_restart_policy_is_no_policy() -> None:
    failing = Failing(after=2.0)
    _, error, end = run_robot([failing, Sleeper()], RestartPolicy(max_restarts=0))
    assert isinstance(error, LayerError)
    assert (end, failing.runs, failing.counters.restarts) == (2.0, [0.0], 0)


# -- with a policy -------------------------------------------------------------------------


class Sender(Layer):
    """Sends ``a`` and ``boom`` down at once, then ``c`` and ``d`` while ``boom`` is handled."""

    async def inner_process(self) -> None:
        if self.counters.sent_internal == 0:
            self.send_down(Note("a", []))
            self.send_down(Note("boom", []))
            self.wake_after(2.0)
        elif self.counters.sent_internal == 2:
            self.send_down(Note("c", []))
            self.send_down(Note("d", []))


class Flaky(Layer):
    """Fails on ``boom`` after working on it for 5 s; records what happens to it, in order."""

    def __init__(self) -> None:
        self.events: list[tuple[str, float]] = []
        self.errors: list[Exception] = []

    async def inner_process(self) -> None:
        self.events.append(("inner_process", self.clock.now()))

    async def store_intra_msg(self, msg: Message) -> None:
        assert isinstance(msg, Note)
        if msg.text == "boom":
            await self.clock.sleep(5.0)
            raise ValueError("cannot handle boom")
        self.events.append((f"got {msg.text}", self.clock.now()))

    async def on_restart(self, error: Exception) -> None:
        self.errors.append(error)
        self.events.append(("on_restart", self.clock.now()))

    def termination_condition(self) -> bool:
        return sum(name.startswith("got") for name, _ in self.events) >= 3


class Ticker(Layer):
    """Wakes every simulated second."""

    def __init__(self) -> None:
        self.ticks: list[float] = []

    async def inner_process(self) -> None:
        self.ticks.append(self.clock.now())
        self.wake_after(1.0)


def test_with_a_policy_the_failed_layer_runs_again_and_keeps_its_queued_messages(
    caplog: pytest.LogCaptureFixture,
) -> None:
    flaky, ticker = Flaky(), Ticker()
    with caplog.at_level(logging.ERROR, logger="cas_async"):
        robot, error, end = run_robot([Sender(), flaky, ticker], RestartPolicy())
    assert error is None
    assert robot.state is RobotState.STOPPED
    assert end == 5.0
    # "boom" was not handled again; "c" and "d", queued while it failed, were delivered.
    assert flaky.events == [
        ("inner_process", 0.0),
        ("got a", 0.0),
        ("on_restart", 5.0),
        ("inner_process", 5.0),  # the layer runs again from the start
        ("got c", 5.0),
        ("got d", 5.0),
        ("inner_process", 5.0),  # after that batch, as usual
    ]
    (cause,) = flaky.errors
    assert isinstance(cause, ValueError)
    assert str(cause) == "cannot handle boom"
    assert flaky.counters.restarts == 1
    assert robot.counters()["restarts"] == 1
    assert ticker.ticks == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]  # the sibling was not disturbed
    (record,) = [r for r in caplog.records if r.name == "cas_async.layer"]
    assert record.getMessage() == (
        "robot 3 Flaky(L1): failed, restarting (restart 1 of 3 allowed within 60 s)"
    )
    assert record.exc_info is not None
    assert record.exc_info[1] is cause


def test_too_many_failures_within_the_window_stop_the_robot() -> None:
    failing, sleeper = Failing(after=1.0), Sleeper()
    _, error, end = run_robot([failing, sleeper], RestartPolicy(max_restarts=2, within=60.0))
    assert isinstance(error, LayerError)
    assert str(error) == "robot 3, layer 0 (Failing) failed: RuntimeError: failure 3"
    assert error.__cause__ is failing.errors[2]
    assert end == 3.0
    assert failing.runs == [0.0, 1.0, 2.0]
    assert [when for when, _ in failing.restarted_with] == [1.0, 2.0]
    assert [cause for _, cause in failing.restarted_with] == failing.errors[:2]
    assert failing.counters.restarts == 2
    assert sleeper.cancelled_at == 3.0


@pytest.mark.parametrize(
    ("spacing", "stopped_at"),
    [
        pytest.param(10.5, None, id="failures-further-apart-than-the-window"),
        pytest.param(9.5, 19.0, id="two-failures-inside-one-window"),
    ],
)
def test_failures_spread_wider_than_the_window_keep_being_restarted(
    spacing: float, stopped_at: float | None
) -> None:
    failing = Failing(after=spacing, failures=5)
    _, error, end = run_robot([failing, Sleeper()], RestartPolicy(max_restarts=1, within=10.0))
    if stopped_at is None:
        assert error is None
        assert failing.counters.restarts == 5
        assert end == 6 * spacing  # five failed runs, then one that finished
    else:
        assert isinstance(error, LayerError)
        assert (end, failing.counters.restarts) == (stopped_at, 1)


def test_an_infinite_window_counts_failures_over_the_robot_s_life() -> None:
    failing = Failing(after=1_000.0)
    _, error, end = run_robot([failing, Sleeper()], RestartPolicy(max_restarts=2, within=math.inf))
    assert isinstance(error, LayerError)
    assert (end, failing.counters.restarts) == (3_000.0, 2)


def test_a_failing_on_restart_stops_the_robot(caplog: pytest.LogCaptureFixture) -> None:
    class Stubborn(Failing):
        async def on_restart(self, error: Exception) -> None:
            await super().on_restart(error)
            raise OSError("cannot reset the gripper")

    stubborn, sleeper = Stubborn(after=4.0), Sleeper()
    with caplog.at_level(logging.ERROR, logger="cas_async"):
        _, error, end = run_robot([stubborn, sleeper], RestartPolicy())
    assert isinstance(error, LayerError)
    assert str(error) == "robot 3, layer 0 (Stubborn) failed: OSError: cannot reset the gripper"
    assert isinstance(error.__cause__, OSError)
    assert end == 4.0
    assert stubborn.runs == [0.0]  # never ran again
    assert sleeper.cancelled_at == 4.0
    messages = [r.getMessage() for r in caplog.records if r.name == "cas_async.layer"]
    assert messages == [
        "robot 3 Stubborn(L0): failed, restarting (restart 1 of 3 allowed within 60 s)",
        "robot 3 Stubborn(L0): on_restart failed, stopping the robot",
    ]
    assert all(r.exc_info is not None for r in caplog.records if r.name == "cas_async.layer")


# -- the policy itself -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        pytest.param({"max_restarts": -1}, "max_restarts must be an int >= 0, got -1", id="neg"),
        pytest.param({"max_restarts": 1.5}, "max_restarts must be an int", id="float"),
        pytest.param({"max_restarts": True}, "max_restarts must be an int", id="bool"),
        pytest.param({"max_restarts": "3"}, "max_restarts must be an int", id="str"),
        pytest.param({"within": 0.0}, r"within must be > 0 simulated seconds, got 0.0", id="0"),
        pytest.param({"within": -5.0}, "within must be > 0", id="negative-window"),
        pytest.param({"within": math.nan}, "within must be > 0", id="nan-window"),
    ],
)
def test_restart_policy_refuses_impossible_limits(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        RestartPolicy(**kwargs)  # type: ignore[arg-type]


def test_restart_policy_defaults_and_immutability() -> None:
    policy = RestartPolicy()
    assert (policy.max_restarts, policy.within) == (3, 60.0)
    assert RestartPolicy(max_restarts=0, within=math.inf).within == math.inf
    with pytest.raises(dataclasses.FrozenInstanceError):
        policy.max_restarts = 5  # type: ignore[misc]


# -- real time ---------------------------------------------------------------------------------


async def test_in_real_time_a_failure_stops_a_robot_whose_other_layer_sleeps_an_hour() -> None:
    class FailsAtOnce(Layer):
        async def inner_process(self) -> None:
            await asyncio.sleep(0)
            raise RuntimeError("broken")

    sleeper = Sleeper()
    robot = Robot(3, [FailsAtOnce(), sleeper], clock=ScaledClock(1.0), messages=STACK_MESSAGES)
    with pytest.raises(LayerError, match=r"layer 0 \(FailsAtOnce\) failed: RuntimeError: broken"):
        async with robot:
            await asyncio.wait_for(robot.run(), 5)  # a guard against hanging, not a measurement
    assert sleeper.cancelled_at is not None
    assert robot.state is RobotState.STOPPED


async def test_a_layer_whose_await_is_cancelled_from_outside_fails_the_robot() -> None:
    driver: asyncio.Future[None] = asyncio.get_running_loop().create_future()

    class Waits(Layer):
        async def inner_process(self) -> None:
            await driver  # e.g. a hardware driver's future, cancelled by someone else

    robot = Robot(1, [Waits(), Layer()], messages=STACK_MESSAGES)
    with pytest.raises(LayerError, match=r"robot 1, layer 0 \(Waits\) failed: CancelledError"):
        async with robot:
            await wait_all_tasks_blocked()
            driver.cancel()
            await asyncio.wait_for(robot.run(), 5)
    assert robot.state is RobotState.STOPPED


async def test_a_layer_failure_is_noted_on_the_block_s_own_exception() -> None:
    class Boom(Layer):
        async def inner_process(self) -> None:
            raise RuntimeError("boom")

    with pytest.raises(KeyError) as caught:
        async with Robot(1, [Boom()], messages=STACK_MESSAGES):
            await wait_all_tasks_blocked()
            raise KeyError("the body's own error")
    assert any("robot 1, layer 0 (Boom) failed" in note for note in caught.value.__notes__)
