"""What the tests of runs across processes share: real processes on loopback, bounded waits.

Every process is a ``python -m cas_async`` subprocess with its output in files (a
worker outliving its world would keep a pipe open), in a session of its own (so the
workers a world spawned can be found and killed with it). Every wait has a
wall-clock limit, and every process still running when a test ends is killed (its
whole process group) and waited for.
"""

from __future__ import annotations

import contextlib
import csv
import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import pytest

ROOT: Final = Path(__file__).resolve().parents[1]
FIRE_BRIGADE: Final = ROOT / "apps" / "fire_brigade" / "scenarios"
SCENARIO: Final = FIRE_BRIGADE / "thesis_5_8_2.toml"
"""The Fire Brigade of §5.8.2: 25 robots, 20 buckets."""

RUN_LIMIT: Final = 45.0
"""Wall seconds a whole run may take (they take 1-8 s; only a hung one comes near)."""
EXIT_LIMIT: Final = 10.0
"""Wall seconds a process may take to exit once its run is over."""
WORKER_EXIT_LIMIT: Final = 8.0
"""Wall seconds a worker may take to exit once its world stopped it, or died (about 1 s)."""
WRONG_KEY_LIMIT: Final = 10.0
"""Wall seconds a worker with another key than the world's may take to say so: its start
(about 1 s), and the 2 s it waits for a signed answer after those that do not check."""
START_LIMIT: Final = 30.0
"""Wall seconds until a world listens, or a run shows progress."""

ENV: Final = {**os.environ, "PYTHONIOENCODING": "utf-8"}


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

    def errors(self) -> str:
        """What it printed on stderr so far."""
        return self.stderr.read_text("utf-8", "replace")

    def running(self) -> bool:
        return self.popen.poll() is None

    def group_alive(self) -> bool:
        """Whether any process of its session (itself, or a worker it spawned) still runs.

        A process that has exited but is not yet reaped (a zombie) does not run: once
        the run has exited, its killed workers are reaped by the system's init, which
        in a container may take a second or two.
        """
        return any(state != "Z" for state in group_states(self.popen.pid).values())

    def children(self) -> list[int]:
        """The ids of the processes it started (the workers of ``run --processes``)."""
        return children_of(self.popen.pid)

    def kill(self) -> None:
        """Kills it and whatever it spawned (stopped ones too), and waits for it."""
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.popen.pid, signal.SIGKILL)
        self.popen.kill()  # nothing when it has exited
        self.popen.wait(timeout=EXIT_LIMIT)


class Processes:
    """Starts ``python -m cas_async`` processes; :meth:`kill_all` ends every one."""

    def __init__(self, directory: Path) -> None:
        self._directory = directory
        self._started: list[Process] = []

    def start(
        self, name: str, *args: str | os.PathLike[str], env: Mapping[str, str] | None = None
    ) -> Process:
        """Starts ``python -m cas_async *args`` from the repository's root.

        ``env``: the environment (default: this one's, with UTF-8 output).
        """
        stdout, stderr = self._directory / f"{name}.out", self._directory / f"{name}.err"
        with stdout.open("wb") as out, stderr.open("wb") as err:
            popen = subprocess.Popen(
                [sys.executable, "-m", "cas_async", *map(str, args)],
                cwd=ROOT,
                env=dict(ENV if env is None else env),
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
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(process.popen.pid, signal.SIGCONT)  # a stopped one cannot die
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
    stderr: str = ""
    wall: float = 0.0
    """Wall seconds from its start to its exit."""


def run_cli(
    logs: Path,
    *args: str | os.PathLike[str],
    limit: float = RUN_LIMIT,
    env: Mapping[str, str] | None = None,
) -> Finished:
    """Runs ``python -m cas_async *args`` to its end; fails the test after ``limit`` seconds."""
    with processes(logs) as started:
        began = time.monotonic()
        process = started.start("run", *args, env=env)
        code = process.wait(limit)
        wall = time.monotonic() - began
        if code is None:
            pytest.fail(f"still running after {limit} s: {args}\n{process.output()}")
        deadline = time.monotonic() + EXIT_LIMIT
        while process.group_alive() and time.monotonic() < deadline:
            time.sleep(0.05)
        return Finished(code, process.output(), process.group_alive(), process.errors(), wall)


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


def wait_for_progress(world: Process, after: float = 0.0) -> None:
    """Waits until the world's progress line shows simulated time ``after`` seconds or later."""
    deadline = time.monotonic() + START_LIMIT
    while time.monotonic() < deadline:
        times = [float(t) for t in re.findall(r"\bt=(-?\d+(?:\.\d+)?)s", world.errors())]
        if any(t >= after for t in times):
            return
        if world.popen.poll() is not None:
            pytest.fail(f"the world exited with {world.popen.returncode}:\n{world.output()}")
        time.sleep(0.05)
    pytest.fail(f"no progress to t={after} after {START_LIMIT} s:\n{world.output()}")


def wait_for_line(process: Process, pattern: str, limit: float = START_LIMIT) -> re.Match[str]:
    """Waits until ``process`` printed a line (stdout or stderr) that ``pattern`` matches."""
    deadline = time.monotonic() + limit
    while time.monotonic() < deadline:
        found = re.search(pattern, process.output())
        if found is not None:
            return found
        if process.popen.poll() is not None:
            found = re.search(pattern, process.output())
            if found is not None:
                return found
            pytest.fail(f"exited with {process.popen.returncode} first:\n{process.output()}")
        time.sleep(0.05)
    pytest.fail(f"no line matching {pattern!r} after {limit} s:\n{process.output()}")


def children_of(pid: int) -> list[int]:
    """The ids of the processes whose parent is ``pid`` (Linux: from ``/proc``)."""
    return sorted(found for found, fields in _stats() if int(fields[1]) == pid)


def group_states(pgid: int) -> dict[int, str]:
    """The state letter (``R``, ``S``, ``Z`` ...) of each process of group ``pgid``."""
    return {found: fields[0] for found, fields in _stats() if int(fields[2]) == pgid}


def _stats() -> Iterator[tuple[int, list[str]]]:
    """Each process's id and the fields of its ``/proc/PID/stat`` from its state on."""
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:  # it exited meanwhile
            continue
        # pid (comm) state ppid pgrp ...: comm may hold spaces and parentheses
        yield int(entry.name), stat[stat.rindex(")") + 2 :].split()


def assert_all_delivered(result: dict[str, Any], target: int = 20) -> None:
    assert result["status"] == "completed", result["error"]
    assert (result["delivered"], result["target"]) == (target, target)


def trace_times(out: Path) -> list[float]:
    """The simulated instants of every row of ``trace.csv``, in file order."""
    with (out / "trace.csv").open(newline="", encoding="utf-8") as file:
        return [float(row["t"]) for row in csv.DictReader(file)]


def control_refusals(result: dict[str, Any]) -> dict[str, int]:
    """The control plane's refusals by reason (``control.*`` in ``protocol_errors``)."""
    errors: dict[str, int] = result["protocol_errors"]
    return {reason: n for reason, n in errors.items() if reason.startswith("control.")}
