"""A simulation across processes (``run --processes``, ``world``, ``worker``), as users run it.

Real subprocesses on loopback, as in ``tests/test_cli.py``: the Fire Brigade of
§5.8.2 (25 robots, 20 buckets) with its robots in two worker processes. Output goes
to files (a worker outliving its world would keep a pipe open), every process
starts a session of its own (so the workers a world spawned can be found and
killed with it), every wait has a wall-clock limit, and every process still
running when a test ends is killed and waited for.
"""

from __future__ import annotations

import os
import re
import signal
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import pytest

from tests.processes_support import (
    EXIT_LIMIT,
    RUN_LIMIT,
    SCENARIO,
    WORKER_EXIT_LIMIT,
    WRONG_KEY_LIMIT,
    assert_all_delivered,
    free_endpoint,
    key_file,
    processes,
    read_results,
    run_cli,
    wait_for_line,
    wait_for_progress,
    wait_listening,
)

pytestmark = pytest.mark.slow  # world and worker processes on Zenoh

pytest.importorskip("zenoh")

ROBOTS: Final = list(range(1, 26))
"""The scenario's robot ids, in the mission's order (worker ``k`` of ``n`` runs ``[k::n]``)."""


# -- run --processes -----------------------------------------------------------------------


def test_virtual_time_with_two_workers_delivers_every_bucket(tmp_path: Path) -> None:
    out = tmp_path / "two"
    finished = run_cli(tmp_path / "two.logs", "run", SCENARIO, "--virtual", "--processes", "2",
                       "--out", out, "--no-plots")  # fmt: skip
    assert finished.code == 0, finished.output
    assert not finished.left_behind, "a worker outlived the run"
    result = read_results(out)
    assert_all_delivered(result)
    assert result["config"]["run"]["virtual"] is True
    assert result["exchanges"] > 0

    alone = tmp_path / "one"
    single = run_cli(tmp_path / "one.logs", "run", SCENARIO, "--virtual", "--out", alone,
                     "--no-plots")  # fmt: skip
    assert single.code == 0, single.output
    reference = read_results(alone)
    assert_all_delivered(reference)
    # The same results as one process with the same seed and latency: every worker's
    # message counts reached the world, and everything else is the same run's
    # (tests/test_processes_identity.py checks trace.csv byte for byte).
    assert result["makespan"] == reference["makespan"]
    assert result["messages_external"] == reference["messages_external"]
    assert result["messages_internal"] == reference["messages_internal"]


def test_scaled_time_with_two_workers_delivers_every_bucket(tmp_path: Path) -> None:
    out = tmp_path / "out"
    finished = run_cli(tmp_path / "logs", "run", SCENARIO, "--time-factor", "10",
                       "--processes", "2", "--out", out, "--no-plots")  # fmt: skip
    assert finished.code == 0, finished.output
    assert not finished.left_behind, "a worker outlived the run"
    result = read_results(out)
    assert_all_delivered(result)
    # The scenario's own transport (udp): between processes it is Zenoh regardless.
    run = result["config"]["run"]
    assert (run["transport"], run["virtual"], run["time_factor"]) == ("udp", False, 10.0)


def test_a_scenario_on_the_memory_transport_runs_across_processes_too(tmp_path: Path) -> None:
    out = tmp_path / "out"
    finished = run_cli(tmp_path / "logs", "run", SCENARIO, "--time-factor", "20",
                       "--transport", "memory", "--processes", "2", "--out", out,
                       "--no-plots")  # fmt: skip
    assert finished.code == 0, finished.output
    assert not finished.left_behind, "a worker outlived the run"
    result = read_results(out)
    assert_all_delivered(result)
    assert result["config"]["run"]["transport"] == "memory"


# -- world and workers by hand ---------------------------------------------------------------


def test_a_world_without_a_key_file_is_a_usage_error(tmp_path: Path) -> None:
    finished = run_cli(tmp_path / "logs", "world", SCENARIO, "--listen", free_endpoint(),
                       "--workers", "2", "--out", tmp_path / "out")  # fmt: skip
    assert finished.code == 2, finished.output
    assert "the following arguments are required: --key-file" in finished.output
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("wait", "said", "limit"),
    [
        # The Zenoh client gives up at once (~0.6 s).
        ("0", ["error: worker: cannot connect to {endpoint}: "], 20.0),
        ("1.5", ["worker: nothing listens at {endpoint} yet; trying again for up to 1.5 s",
                 "error: worker: cannot connect to {endpoint} within 1.5 s: "], 30.0),
    ],
    ids=["at-once", "after-waiting"],
)  # fmt: skip
def test_a_worker_with_no_world_at_its_endpoint_waits_as_told_then_exits_naming_it(
    tmp_path: Path, wait: str, said: list[str], limit: float
) -> None:
    endpoint = free_endpoint()  # nothing listens there
    key = key_file(tmp_path / "swarm.key")
    started = time.monotonic()
    finished = run_cli(tmp_path / "logs", "worker", "--connect", endpoint, "--key-file", key,
                       "--wait", wait)  # fmt: skip
    took = time.monotonic() - started
    assert finished.code == 2, finished.output
    lines = finished.output.splitlines()[: len(said)]  # what it says first, in this order
    assert len(lines) == len(said), finished.output
    for line, expected in zip(lines, said, strict=True):
        assert line.startswith(expected.format(endpoint=endpoint)), finished.output
    assert "Traceback" not in finished.output
    assert float(wait) <= took < limit


@pytest.mark.parametrize("wait", ["-1", "nan", "1e9", "soon"])
def test_a_worker_refuses_an_absurd_wait(tmp_path: Path, wait: str) -> None:
    finished = run_cli(tmp_path / "logs", "worker", "--connect", free_endpoint(), "--wait", wait)
    assert finished.code == 2, finished.output
    assert f"argument --wait: expected seconds from 0 to 86400 (a day), got {wait!r}" in (
        finished.output
    )


def test_workers_started_before_their_world_wait_for_it_and_run(tmp_path: Path) -> None:
    """A launcher may start every process at once: workers wait for the world to listen."""
    key, endpoint, out = key_file(tmp_path / "swarm.key"), free_endpoint(), tmp_path / "out"
    with processes(tmp_path / "logs") as started:
        waiting = ("worker", "--connect", endpoint, "--key-file", key, "--wait", str(RUN_LIMIT))
        workers = [started.start(f"worker{k}", *waiting) for k in range(2)]
        for worker in workers:
            wait_for_line(worker, f"nothing listens at {re.escape(endpoint)} yet")
        world = started.start(
            "world", "world", SCENARIO, "--listen", endpoint, "--workers", "2",
            "--key-file", key, "--virtual", "--out", out, "--no-plots",
        )  # fmt: skip
        assert world.wait(RUN_LIMIT) == 0, world.output()
        for worker in workers:
            assert worker.wait(EXIT_LIMIT) == 0, worker.output()
    assert_all_delivered(read_results(out))


def test_workers_started_by_hand_with_the_key_run_it_and_a_wrong_key_is_told_at_once(
    tmp_path: Path,
) -> None:
    key, wrong = key_file(tmp_path / "swarm.key"), key_file(tmp_path / "wrong.key", "cd" * 32)
    endpoint, out = free_endpoint(), tmp_path / "out"
    with processes(tmp_path / "logs") as started:
        world = started.start(
            "world", "world", SCENARIO, "--listen", endpoint, "--workers", "2",
            "--key-file", key, "--set", "run.time_factor=10", "--out", out, "--no-plots",
        )  # fmt: skip
        wait_listening(endpoint, world)
        intruder = started.start("intruder", "worker", "--connect", endpoint, "--key-file", wrong)
        # Its hello does not check: the world's answer, signed with the world's key, does
        # not check for it either; it says so on one line and leaves, without a place.
        assert intruder.wait(WRONG_KEY_LIMIT) == 2, intruder.output()
        assert "signs with another key" in intruder.output()
        assert "Traceback" not in intruder.output()
        assert "does not check against this world's key" in world.output()
        workers = [
            started.start(f"worker{k}", "worker", "--connect", endpoint, "--key-file", key)
            for k in range(2)
        ]
        assert world.wait(RUN_LIMIT) == 0, world.output()
        for worker in workers:
            assert worker.wait(EXIT_LIMIT) == 0, worker.output()
        assert "worker 0 of 2" in workers[0].output() + workers[1].output()
    result = read_results(out)
    assert_all_delivered(result)
    assert result["config"]["run"]["time_factor"] == 10.0


@dataclass(frozen=True)
class LostWorker:
    """What happened when one of two workers was killed during a run."""

    world_code: int | None
    world_output: str
    results: dict[str, Any] | None
    other_code: int | None
    killed_code: int | None
    shares: dict[int, list[int]]
    """The robots each worker said it runs (a worker started by hand says so)."""


@pytest.fixture(scope="module")
def lost_worker(tmp_path_factory: pytest.TempPathFactory) -> LostWorker:
    """A run of a world and two workers started by hand, one of them killed midway.

    Records what happened, for the tests below to judge; fails only if the run
    never gets under way.
    """
    tmp = tmp_path_factory.mktemp("lost")
    key, endpoint, out = key_file(tmp / "swarm.key"), free_endpoint(), tmp / "out"
    with processes(tmp / "logs") as started:
        world = started.start(
            "world", "world", SCENARIO, "--listen", endpoint, "--workers", "2",
            "--key-file", key, "--set", "run.time_factor=5", "--out", out, "--no-plots",
        )  # fmt: skip
        wait_listening(endpoint, world)
        workers = [
            started.start(f"worker{k}", "worker", "--connect", endpoint, "--key-file", key)
            for k in range(2)
        ]
        wait_for_progress(world)  # about 25 simulated seconds to go, 5 wall seconds
        time.sleep(0.5)
        os.kill(workers[1].popen.pid, signal.SIGKILL)
        world_code = world.wait(RUN_LIMIT)
        other_code = workers[0].wait(WORKER_EXIT_LIMIT)
        killed_code = workers[1].wait(WORKER_EXIT_LIMIT)
        output = world.output()
        shares = dict(_share(worker.output()) for worker in workers)
    results = read_results(out) if (out / "results.json").exists() else None
    return LostWorker(world_code, output, results, other_code, killed_code, shares)


_SHARE: Final = re.compile(r"worker (\d) of 2: its (\d+) robots: ([\d, ]+)")
_LOST: Final = re.compile(r"worker (\d) is gone\b.*?\bits (\d+) robots are lost: ([\d, ]+)")


def _share(text: str) -> tuple[int, list[int]]:
    """The worker and the robots a worker says it runs as it joins."""
    found = _SHARE.search(text)
    assert found is not None, text
    robots = [int(robot) for robot in found.group(3).split(",")]
    assert int(found.group(2)) == len(robots)
    return int(found.group(1)), robots


def _lost_robots(text: str, shares: dict[int, list[int]]) -> tuple[int, list[int]]:
    """The worker and the robots a ``worker N is gone`` message names: its share."""
    found = _LOST.search(text)
    assert found is not None, text
    worker, count = int(found.group(1)), int(found.group(2))
    robots = [int(robot) for robot in found.group(3).split(",")]
    assert robots == shares[worker]
    assert count == len(robots)
    assert sorted(shares[0] + shares[1]) == ROBOTS
    return worker, robots


def test_a_killed_worker_ends_the_run_the_world_names_it_and_its_robots(
    lost_worker: LostWorker,
) -> None:
    assert lost_worker.killed_code == -signal.SIGKILL
    assert lost_worker.world_code is not None, "the world still ran 45 s after the loss"
    assert lost_worker.world_code != 0, lost_worker.world_output
    _lost_robots(lost_worker.world_output, lost_worker.shares)


def test_a_killed_worker_leaves_results_of_a_failed_run(lost_worker: LostWorker) -> None:
    assert lost_worker.results is not None, lost_worker.world_output
    assert lost_worker.results["status"] == "failed"
    assert lost_worker.results["delivered"] < 20
    _lost_robots(lost_worker.results["error"], lost_worker.shares)


def test_a_killed_worker_leaves_no_process_running(lost_worker: LostWorker) -> None:
    assert lost_worker.world_code is not None
    assert lost_worker.killed_code is not None
    assert lost_worker.other_code is not None, "the other worker still runs"


def test_a_worker_whose_world_is_killed_exits(tmp_path: Path) -> None:
    key, endpoint = key_file(tmp_path / "swarm.key"), free_endpoint()
    with processes(tmp_path / "logs") as started:
        world = started.start(
            "world", "world", SCENARIO, "--listen", endpoint, "--workers", "1",
            "--key-file", key, "--set", "run.time_factor=5", "--out", tmp_path / "out",
            "--no-plots",
        )  # fmt: skip
        wait_listening(endpoint, world)
        worker = started.start("worker", "worker", "--connect", endpoint, "--key-file", key)
        wait_for_progress(world)
        os.kill(world.popen.pid, signal.SIGKILL)
        assert world.wait(EXIT_LIMIT) == -signal.SIGKILL
        code = worker.wait(WORKER_EXIT_LIMIT)
        assert code is not None, f"still running {WORKER_EXIT_LIMIT} s after its world died"
        assert code != 0
        assert "the world is gone" in worker.output()
