"""A simulation across processes (``run --processes``, ``world``, ``worker``), as users run it.

Real subprocesses on loopback, as in ``tests/test_cli.py``: the Fire Brigade of
§5.8.2 (25 robots, 20 buckets) with its robots in two worker processes. Output goes
to files (a worker outliving its world would keep a pipe open), every process
starts a session of its own (so the workers a world spawned can be found and
killed with it), every wait has a wall-clock limit, and every process still
running when a test ends is killed and waited for.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import pytest

pytestmark = pytest.mark.slow  # world and worker processes on Zenoh

pytest.importorskip("zenoh")


ROOT: Final = Path(__file__).resolve().parents[1]
SCENARIO: Final = ROOT / "apps" / "fire_brigade" / "scenarios" / "thesis_5_8_2.toml"
ROBOTS: Final = list(range(1, 26))
"""The scenario's robot ids, in the mission's order (worker ``k`` of ``n`` runs ``[k::n]``)."""

RUN_LIMIT: Final = 45.0
"""Wall seconds a whole run may take (they take 1-8 s; only a hung one comes near)."""
EXIT_LIMIT: Final = 10.0
"""Wall seconds a process may take to exit once its run is over."""
WORKER_EXIT_LIMIT: Final = 8.0
"""Wall seconds a worker may take to exit once its world stopped it, or died (about 1 s)."""
WRONG_KEY_LIMIT: Final = 15.0
"""Wall seconds a worker with another key than the world's may take to say so (about 1 s)."""
START_LIMIT: Final = 30.0
"""Wall seconds until a world listens, or a run shows progress."""

_ENV: Final = {**os.environ, "PYTHONIOENCODING": "utf-8"}


@dataclass
class Process:
    """A ``python -m cas_async`` process with its output in two files."""

    popen: subprocess.Popen[bytes]
    stdout: Path
    stderr: Path

    def wait(self, limit: float) -> int | None:
        """The exit code, or ``None`` if it is still running after ``limit`` seconds."""
        try:
            return self.popen.wait(timeout=limit)
        except subprocess.TimeoutExpired:
            return None

    def output(self) -> str:
        """What it printed so far, stdout then stderr."""
        return self.stdout.read_text("utf-8", "replace") + self.stderr.read_text("utf-8", "replace")

    def group_alive(self) -> bool:
        """Whether any process of its session (itself, or a worker it spawned) still runs."""
        try:
            os.killpg(self.popen.pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:  # pragma: no cover - a reused id of another user's group
            return False
        return True

    def kill(self) -> None:
        """Kills it and whatever it spawned, and waits for it."""
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.popen.pid, signal.SIGKILL)
        self.popen.kill()  # nothing when it has exited
        self.popen.wait(timeout=EXIT_LIMIT)


class Processes:
    """Starts ``python -m cas_async`` processes; :meth:`kill_all` ends every one."""

    def __init__(self, directory: Path) -> None:
        self._directory = directory
        self._started: list[Process] = []

    def start(self, name: str, *args: str | os.PathLike[str]) -> Process:
        stdout, stderr = self._directory / f"{name}.out", self._directory / f"{name}.err"
        with stdout.open("wb") as out, stderr.open("wb") as err:
            popen = subprocess.Popen(
                [sys.executable, "-m", "cas_async", *map(str, args)],
                cwd=ROOT,
                env=_ENV,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=err,
                start_new_session=True,
            )
        process = Process(popen, stdout, stderr)
        self._started.append(process)
        return process

    def kill_all(self) -> None:
        for process in self._started:
            process.kill()


@contextlib.contextmanager
def processes(directory: Path) -> Iterator[Processes]:
    directory.mkdir(parents=True, exist_ok=True)
    started = Processes(directory)
    try:
        yield started
    finally:
        started.kill_all()


@dataclass(frozen=True)
class Finished:
    code: int
    output: str
    left_behind: bool
    """Whether a process it spawned (a worker) was still running after it exited."""


def run_cli(logs: Path, *args: str | os.PathLike[str]) -> Finished:
    """Runs ``python -m cas_async *args`` to its end; fails the test after :data:`RUN_LIMIT`."""
    with processes(logs) as started:
        process = started.start("run", *args)
        code = process.wait(RUN_LIMIT)
        if code is None:
            pytest.fail(f"still running after {RUN_LIMIT} s: {args}\n{process.output()}")
        deadline = time.monotonic() + EXIT_LIMIT
        while process.group_alive() and time.monotonic() < deadline:
            time.sleep(0.05)
        return Finished(code, process.output(), process.group_alive())


def read_results(out: Path) -> dict[str, Any]:
    data = json.loads((out / "results.json").read_text(encoding="utf-8"))
    assert isinstance(data, dict)
    return data


def key_file(path: Path, secret: str = "ab" * 32) -> Path:
    path.write_text(secret + "\n")
    path.chmod(0o600)  # else a KeyFileWarning
    return path


def free_endpoint() -> str:
    """A loopback endpoint whose port was free a moment ago."""
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{probe.getsockname()[1]}"


def wait_listening(endpoint: str, world: Process) -> None:
    """Waits until the world's router accepts connections (a worker that finds none gives up)."""
    port = int(endpoint.rsplit(":", 1)[1])
    deadline = time.monotonic() + START_LIMIT
    while time.monotonic() < deadline:
        if world.popen.poll() is not None:
            pytest.fail(f"the world exited with {world.popen.returncode}:\n{world.output()}")
        with socket.socket() as probe:
            if probe.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    pytest.fail(f"the world does not listen on {endpoint} after {START_LIMIT} s")


def wait_for_progress(world: Process) -> None:
    """Waits until the world's progress line shows simulated time passing."""
    deadline = time.monotonic() + START_LIMIT
    while time.monotonic() < deadline:
        if re.search(r"t=\d", world.stderr.read_text("utf-8", "replace")):
            return
        if world.popen.poll() is not None:
            pytest.fail(f"the world exited with {world.popen.returncode}:\n{world.output()}")
        time.sleep(0.05)
    pytest.fail(f"no progress after {START_LIMIT} s:\n{world.output()}")


def assert_all_delivered(result: dict[str, Any]) -> None:
    assert result["status"] == "completed", result["error"]
    assert (result["delivered"], result["target"]) == (20, 20)


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


def test_a_worker_with_no_world_at_its_endpoint_exits_naming_it(tmp_path: Path) -> None:
    endpoint = free_endpoint()  # nothing listens there
    key = key_file(tmp_path / "swarm.key")
    started = time.monotonic()
    finished = run_cli(tmp_path / "logs", "worker", "--connect", endpoint, "--key-file", key)
    assert finished.code == 2, finished.output
    assert finished.output.startswith(f"error: worker: cannot connect to {endpoint}")
    assert time.monotonic() - started < 20  # the Zenoh client gives up at once (~0.6 s)


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
