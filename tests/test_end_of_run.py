"""Every run ends by one rule, however it is run (``RunStatus``; docs/app-contract.md).

A run is *completed* at the instant its objective is met, whatever the robots do
after (they stop, go quiet, or keep busy); *stopped* when every robot stopped before
that; *timed out* at ``run.max_time``, or at once when nothing can happen any more.
Two apps of the shapes that broke it, written on the public API (``end_of_run/``):

* ``contract_net``: a manager auctions tasks; the top layer's ``termination_condition``
  holds once every task is done (``tasks.stop_when_done``), as the tutorial's does;
* ``area_coverage``: robots visit every cell of a grid, then go quiet
  (``explore.when_done = "quiet"``), stop through their termination condition
  (``"terminate"``) or call ``robot.stop()`` (``"stop"``).

Each is run in one process (sampled: no latency, or scaled time; windowed: the
default latency on virtual time), across two worker processes (virtual and scaled
time), and as an RL episode.
"""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path
from typing import Final

import numpy as np
import pytest

from cas_async.scenario import RunStatus
from cas_async.testing import run_scenario_file

HERE: Final = Path(__file__).parent / "end_of_run"
CONTRACT: Final = HERE / "contract_net.toml"
COVERAGE: Final = HERE / "area_coverage.toml"
GATHERING: Final = Path(__file__).parents[1] / "examples" / "gathering" / "gathering.toml"

ONE_ROBOT: Final = ("robots.count=1",)
STOP: Final = ('explore.when_done="stop"',)
TERMINATE: Final = ('explore.when_done="terminate"',)
QUIET: Final = ('explore.when_done="quiet"',)
EARLY: Final = ('layers.contract="contract_net.probes:EarlyContract"',)
LAZY: Final = ('layers.contract="contract_net.probes:LazyContract"', "tasks.stop_when_done=false")

COMPLETING: Final = [
    pytest.param(CONTRACT, ONE_ROBOT, id="one-robot-stops-when-done"),
    pytest.param(CONTRACT, (), id="layers-stop-when-done"),
    pytest.param(CONTRACT, ("tasks.stop_when_done=false",), id="layers-keep-going"),
    pytest.param(COVERAGE, QUIET, id="swarm-goes-quiet"),
    pytest.param(COVERAGE, TERMINATE, id="swarm-terminates"),
    pytest.param(COVERAGE, STOP, id="robots-call-stop"),
    pytest.param(GATHERING, (), id="tutorial"),
]
MODES: Final = [
    pytest.param(("network.latency=0",), id="sampled"),
    pytest.param((), id="windowed"),
]


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize(("scenario", "overrides"), COMPLETING)
def test_a_run_whose_objective_is_met_completes_whatever_the_robots_do_after(
    scenario: Path, overrides: tuple[str, ...], mode: tuple[str, ...]
) -> None:
    result = run_scenario_file(scenario, *overrides, *mode).result
    assert (result.status, result.error) == (RunStatus.COMPLETED, None)
    assert result.delivered == result.target
    assert result.makespan is not None
    assert result.makespan <= result.sim_time


@pytest.mark.parametrize("mode", MODES)
def test_a_run_whose_robots_all_stop_first_is_stopped_there(mode: tuple[str, ...]) -> None:
    outcome = run_scenario_file(CONTRACT, *EARLY, *mode)
    result = outcome.result
    assert (result.status, result.error, result.traceback) == (RunStatus.STOPPED, None, None)
    assert result.delivered < result.target
    assert result.sim_time < 1.0  # where the last robot stopped, not max_time
    assert outcome.trace.times[-1] == result.sim_time  # the trace ends there too


@pytest.mark.parametrize("mode", MODES)
def test_a_swarm_that_can_never_complete_times_out_at_once(mode: tuple[str, ...]) -> None:
    result = run_scenario_file(CONTRACT, *LAZY, *mode).result
    assert result.status is RunStatus.TIMED_OUT
    assert result.sim_time == 300.0  # run.max_time: nothing could happen any more
    assert result.wall_time < 30  # at once, not after max_time of anything


@pytest.mark.parametrize(
    ("overrides", "status"),
    [
        pytest.param(ONE_ROBOT, RunStatus.COMPLETED, id="one-robot-stops-when-done"),
        pytest.param(STOP, RunStatus.COMPLETED, id="robots-call-stop"),
        pytest.param(EARLY, RunStatus.STOPPED, id="stopped-first"),
    ],
)
def test_on_scaled_time_too(overrides: tuple[str, ...], status: RunStatus) -> None:
    scenario = COVERAGE if overrides == STOP else CONTRACT
    result = run_scenario_file(
        scenario, *overrides, "run.virtual=false", 'run.transport="memory"', "run.time_factor=100",
        virtual=False,
    ).result  # fmt: skip
    assert result.status is status, result.error


def test_a_stopped_run_says_so_in_the_summary_and_exits_1(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "cas_async", "run", str(CONTRACT), "--no-plots",
         "--out", str(tmp_path), "--set", EARLY[0]],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert done.returncode == 1, done.stderr
    assert ": STOPPED (every robot stopped before the target)" in done.stdout
    assert "Traceback" not in done.stdout + done.stderr


# -- across processes --------------------------------------------------------------------

ACROSS: Final = [
    pytest.param(CONTRACT, (), "completed", id="layers-stop-when-done"),
    pytest.param(CONTRACT, ("robots.count=2",), "completed", id="two-robots-stop-when-done"),
    pytest.param(COVERAGE, STOP, "completed", id="robots-call-stop"),
    pytest.param(COVERAGE, TERMINATE, "completed", id="swarm-terminates"),
    pytest.param(GATHERING, (), "completed", id="tutorial"),
    pytest.param(CONTRACT, EARLY, "STOPPED", id="stopped-first"),
]


def _run(scenario: Path, out: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "cas_async", "run", str(scenario), "--no-plots", "--out", str(out),
         "--set", "run.window_limit=10", *args],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize(("scenario", "overrides", "status"), ACROSS)
def test_across_processes_a_run_ends_as_in_one_process(
    scenario: Path, overrides: tuple[str, ...], status: str, tmp_path: Path
) -> None:
    pytest.importorskip("zenoh")
    sets = [arg for override in overrides for arg in ("--set", override)]
    one = _run(scenario, tmp_path / "one", "--virtual", *sets)
    two = _run(scenario, tmp_path / "two", "--virtual", "--processes", "2", *sets)
    for done in (one, two):
        assert f": {status}" in done.stdout, done.stdout[-800:] + done.stderr[-800:]
        assert "frozen or cut off" not in done.stdout  # never a wait for window_limit
    assert (tmp_path / "one" / "trace.csv").read_bytes() == (
        tmp_path / "two" / "trace.csv"
    ).read_bytes()


@pytest.mark.slow
@pytest.mark.parametrize(
    ("scenario", "overrides", "status"),
    [
        pytest.param(CONTRACT, ("robots.count=2",), "completed", id="layers-stop-when-done"),
        pytest.param(COVERAGE, TERMINATE, "completed", id="swarm-terminates"),
        pytest.param(CONTRACT, EARLY, "STOPPED", id="stopped-first"),
    ],
)
def test_across_processes_on_scaled_time_too(
    scenario: Path, overrides: tuple[str, ...], status: str, tmp_path: Path
) -> None:
    pytest.importorskip("zenoh")
    sets = [arg for override in overrides for arg in ("--set", override)]
    done = _run(scenario, tmp_path, "--processes", "2", "--time-factor", "20", *sets)
    assert f": {status}" in done.stdout, done.stdout[-800:] + done.stderr[-800:]


# -- as a learning environment -----------------------------------------------------------


def _episode(layer: str, *overrides: str) -> tuple[int, dict[str, bool], dict[str, bool], object]:
    """Steps a contract-net episode (dt = 1, max_time = 300) until it ends: how it ended."""
    pytest.importorskip("pettingzoo")
    from gymnasium.spaces import Box, Discrete

    from cas_async.rl import ParallelSwarmEnv

    if str(HERE) not in sys.path:  # as the loader finds the app beside its scenario
        sys.path.append(str(HERE))
    module, _, name = layer.partition(":")
    policy = getattr(importlib.import_module(module), name)
    env = ParallelSwarmEnv(
        str(CONTRACT),
        level="contract",
        layer=policy,
        observe=lambda layer: np.array([len(layer.queue)], dtype=np.float32),
        reward=lambda layer, outcome: float(outcome.gained),
        observation_space=Box(0.0, 100.0, (1,), np.float32),
        action_space=Discrete(2),
        dt=1.0,
        overrides=list(overrides),
    )
    steps, terminated, truncated = 0, {}, {}
    with env:
        env.reset(seed=1)
        while env.agents and steps <= 305:
            _, _, terminated, truncated, _ = env.step({agent: 0 for agent in env.agents})
            steps += 1
        return steps, terminated, truncated, None if env.result is None else env.result.status


@pytest.mark.parametrize(
    ("layer", "stop", "status", "ended"),
    [
        pytest.param("contract_net.learned:LearnedContract", False, RunStatus.COMPLETED,
                     "terminated", id="completes-and-keeps-going"),
        pytest.param("contract_net.learned:LearnedContract", True, RunStatus.COMPLETED,
                     "terminated", id="completes-and-stops"),
        pytest.param("contract_net.learned:LazyLearned", False, RunStatus.TIMED_OUT,
                     "truncated", id="never-completes"),
    ],
)  # fmt: skip
def test_an_rl_episode_ends_within_its_max_time(
    layer: str, stop: bool, status: RunStatus, ended: str
) -> None:
    steps, terminated, truncated, got = _episode(
        layer, "robots.count=1", "tasks.count=20", f"tasks.stop_when_done={str(stop).lower()}"
    )
    assert got is status
    assert steps <= 300  # run.max_time / dt
    assert all((terminated if ended == "terminated" else truncated).values())
