"""Runs across processes that cannot run, or stop running, fail fast and truthfully.

Each case is a run of the command line as users start it (``run --processes`` or a
world and workers by hand), made to fail one way: workers that cannot import the
app, a worker with another key than the world's, more processes than robots, no
latency, a frozen worker, a worker killed during set-up. Each must end within a
few seconds (or ``run.window_limit``), say why in one line on stderr (no
traceback), exit 2 (configuration) or 1 (the run), and leave a ``results.json``
with its status and error.

Every process is started in a session of its own and killed with its group at the
end of its case (a stopped one is continued first, so that it can die).
"""

from __future__ import annotations

import os
import re
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import pytest

from tests.processes_support import (
    ENV,
    ROOT,
    SCENARIO,
    WORKER_EXIT_LIMIT,
    Process,
    free_endpoint,
    key_file,
    processes,
    read_results,
    wait_for_line,
    wait_for_progress,
    wait_listening,
)

pytestmark = pytest.mark.slow  # worlds and workers that fail, some after seconds of waiting

pytest.importorskip("zenoh")

FAST: Final = 20.0
"""Wall seconds within which a run that cannot start has said so ("a few seconds" on a
loaded 2-core machine: a Python process with Zenoh takes 1-2 s to start)."""
GIVE_UP: Final = 45.0
"""Wall seconds a case waits for the world before it kills everything (a hang)."""
WINDOW_LIMIT: Final = 8.0
"""``run.window_limit`` of the frozen-worker cases.

A world started by hand also waits that long for its workers to be ready: at a load
of 8 two workers (Python, Zenoh, the robots) were not ready within 3 s, and the
world gave up before anything froze. Below Zenoh's lease (10 s: a frozen worker's
token goes then, and the world names it 2 s later), so that the limit is what
finds the freeze.
"""
FIVE_ROBOTS: Final = ("--set", "transporters.count=1", "--set", "mission.buckets=2")
"""thesis_5_8_2 with 2 Generators, 2 Sinks and 1 Transporter."""
BOX_MOVING: Final = ROOT / "apps" / "box_moving" / "scenarios" / "thesis_4_4.toml"
_PROGRESS: Final = re.compile(r"^t=-?\d")
_SHARE: Final = re.compile(r"worker (\d+) of (\d+): its (\d+) robots: ([\d, ]+)")


@dataclass
class Outcome:
    """How one failing run ended, seen from its world (or the ``run`` command)."""

    code: int | None
    """The exit code; ``None``: still running after :data:`GIVE_UP` s (then killed)."""
    wall: float
    """Wall seconds from the failure (the start, or the freeze) to the exit."""
    stderr: str
    stdout: str
    results: dict[str, Any] | None
    facts: dict[str, Any] = field(default_factory=dict)
    """What else the case saw (a worker's share, a frozen worker's exit...)."""


def _finish(process: Process, began: float, out: Path, **facts: Any) -> Outcome:
    code = process.wait(max(0.0, GIVE_UP - (time.monotonic() - began)))
    wall = time.monotonic() - began
    results = read_results(out) if (out / "results.json").exists() else None
    return Outcome(code, wall, process.errors(), process.stdout.read_text("utf-8", "replace"),
                   results, facts)  # fmt: skip


def _app_package(tmp: Path, name: str, body: str) -> tuple[Path, Path]:
    """An app package in a folder of its own and a scenario using it (elsewhere).

    Returns the folder to put on ``PYTHONPATH`` and the scenario file.
    """
    packages = tmp / "packages"
    (packages / name).mkdir(parents=True)
    (packages / name / "__init__.py").write_text(body)
    scenarios = tmp / "scenarios"
    scenarios.mkdir()
    scenario = scenarios / f"{name}.toml"
    scenario.write_text(f'extends = "{SCENARIO.as_posix()}"\napp = "{name}"\n')
    return packages, scenario


def _with_path(folder: Path) -> dict[str, str]:
    return {**ENV, "PYTHONPATH": os.pathsep.join([str(folder), ENV.get("PYTHONPATH", "")])}


def _run(tmp: Path, *args: str | os.PathLike[str], env: dict[str, str] | None = None) -> Outcome:
    out = tmp / "out"
    with processes(tmp / "logs") as started:
        began = time.monotonic()
        process = started.start("run", "run", *args, "--out", out, "--no-plots", env=env)
        return _finish(process, began, out)


# -- the cases ---------------------------------------------------------------------------


def spawned_workers_cannot_import_the_app(tmp: Path) -> Outcome:
    """``run --processes 2`` whose workers fail to import the app (the world can)."""
    folder, scenario = _app_package(tmp, "picky_app", (
        "import sys\n"
        "if 'worker' in sys.argv:  # as on a host without the robots' driver\n"
        "    raise ImportError('no driver for the robots on this host')\n"
        "from apps.fire_brigade import app\n"
    ))  # fmt: skip
    return _run(tmp, scenario, "--virtual", "--processes", "2", env=_with_path(folder))


def workers_by_hand_cannot_import_the_app(tmp: Path) -> Outcome:
    """A world that imports the app (on its ``PYTHONPATH``), two workers that cannot."""
    folder, scenario = _app_package(tmp, "local_app", "from apps.fire_brigade import app\n")
    key, endpoint, out = key_file(tmp / "swarm.key"), free_endpoint(), tmp / "out"
    with processes(tmp / "logs") as started:
        world = started.start(
            "world", "world", scenario, "--listen", endpoint, "--workers", "2",
            "--key-file", key, "--virtual", "--out", out, "--no-plots",
            env=_with_path(folder),
        )  # fmt: skip
        wait_listening(endpoint, world)
        began = time.monotonic()
        # --wait 0: the world may be gone before the second worker connects; it then
        # exits at once (by default it would try again for 30 s, see test_distributed).
        at_once = ("worker", "--connect", endpoint, "--key-file", key, "--wait", "0")
        workers = [started.start(f"worker{k}", *at_once) for k in range(2)]
        codes = [worker.wait(WORKER_EXIT_LIMIT + 20) for worker in workers]
        return _finish(world, began, out, worker_codes=codes,
                       worker_errors=[worker.errors() for worker in workers])  # fmt: skip


def a_worker_with_another_key(tmp: Path) -> Outcome:
    """A world and two workers by hand: one with the world's key, one with another.

    The outcome is the refused worker's: the world goes on waiting for a worker with
    its key (a stranger's hello must not end a run), and says what it refused.
    """
    key, wrong = key_file(tmp / "swarm.key"), key_file(tmp / "wrong.key", "cd" * 32)
    endpoint, out = free_endpoint(), tmp / "out"
    with processes(tmp / "logs") as started:
        world = started.start(
            "world", "world", SCENARIO, "--listen", endpoint, "--workers", "2",
            "--key-file", key, "--virtual", "--out", out, "--no-plots",
        )  # fmt: skip
        wait_listening(endpoint, world)
        began = time.monotonic()
        started.start("worker0", "worker", "--connect", endpoint, "--key-file", key)
        intruder = started.start("worker1", "worker", "--connect", endpoint, "--key-file", wrong)
        outcome = _finish(intruder, began, tmp / "nowhere")
        outcome.facts["world_running"] = world.running()
        outcome.facts["world_said"] = world.errors()
        return outcome


def more_processes_than_robots(tmp: Path) -> Outcome:
    return _run(tmp, SCENARIO, "--virtual", *FIVE_ROBOTS, "--processes", "6")


def a_thousand_processes(tmp: Path) -> Outcome:
    return _run(tmp, SCENARIO, "--virtual", "--processes", "1000")


def zero_processes(tmp: Path) -> Outcome:
    return _run(tmp, SCENARIO, "--virtual", "--processes", "0")


def no_latency(tmp: Path) -> Outcome:
    return _run(tmp, SCENARIO, "--virtual", "--set", "network.latency=0", "--processes", "2")


def an_objective_that_is_not_distributable(tmp: Path) -> Outcome:
    return _run(tmp, BOX_MOVING, "--virtual", "--processes", "2")


def _frozen(tmp: Path, *timing: str) -> Outcome:
    """A world and two workers by hand; worker 1 is stopped (SIGSTOP) once the run goes."""
    key, endpoint, out = key_file(tmp / "swarm.key"), free_endpoint(), tmp / "out"
    with processes(tmp / "logs") as started:
        world = started.start(
            "world", "world", SCENARIO, "--listen", endpoint, "--workers", "2",
            "--key-file", key, *timing, "--set", f"run.window_limit={WINDOW_LIMIT}",
            "--out", out, "--no-plots",
        )  # fmt: skip
        wait_listening(endpoint, world)
        workers = [
            started.start(f"worker{k}", "worker", "--connect", endpoint, "--key-file", key)
            for k in range(2)
        ]
        shares = {}
        for worker in workers:
            found = wait_for_line(worker, _SHARE.pattern)
            shares[int(found.group(1))] = [int(r) for r in found.group(4).split(",")]
        frozen = next(w for w in workers if "worker 1 of 2" in w.output())
        wait_for_progress(world, after=1.0)
        began = time.monotonic()
        os.kill(frozen.popen.pid, signal.SIGSTOP)
        try:
            outcome = _finish(world, began, out, shares=shares)
        finally:
            os.kill(frozen.popen.pid, signal.SIGCONT)
        # Continued, it finds its world gone, and leaves.
        outcome.facts["frozen_code"] = frozen.wait(WORKER_EXIT_LIMIT + WINDOW_LIMIT)
        outcome.facts["frozen_errors"] = frozen.errors()
        return outcome


def a_frozen_worker_on_virtual_time(tmp: Path) -> Outcome:
    return _frozen(tmp, "--virtual")


def a_frozen_worker_on_scaled_time(tmp: Path) -> Outcome:
    return _frozen(tmp, "--set", "run.time_factor=5")


def a_spawned_worker_killed_during_set_up(tmp: Path) -> Outcome:
    """``run --processes 2``: a worker is killed as soon as it exists, before it is ready."""
    out = tmp / "out"
    with processes(tmp / "logs") as started:
        process = started.start("run", "run", SCENARIO, "--virtual", "--processes", "2",
                                "--out", out, "--no-plots")  # fmt: skip
        deadline = time.monotonic() + GIVE_UP
        while not process.children() and time.monotonic() < deadline and process.running():
            time.sleep(0.01)
        children = process.children()
        assert children, process.output()
        began = time.monotonic()
        os.kill(children[0], signal.SIGKILL)
        return _finish(process, began, out)


def a_worker_by_hand_killed_during_set_up(tmp: Path) -> Outcome:
    """A world waiting for two workers: the one that came is killed while it waits for the other.

    (Killed as it builds its robots, it would race its own ``Ready``: the world waits
    for a second worker all the same, so the run is still being set up either way.)
    """
    key, endpoint, out = key_file(tmp / "swarm.key"), free_endpoint(), tmp / "out"
    with processes(tmp / "logs") as started:
        world = started.start(
            "world", "world", SCENARIO, "--listen", endpoint, "--workers", "2",
            "--key-file", key, "--virtual", "--out", out, "--no-plots",
        )  # fmt: skip
        wait_listening(endpoint, world)
        first = started.start("worker0", "worker", "--connect", endpoint, "--key-file", key)
        wait_for_line(first, _SHARE.pattern)  # welcomed: it builds its robots, says it is ready
        time.sleep(2.0)
        began = time.monotonic()
        os.kill(first.popen.pid, signal.SIGKILL)
        return _finish(world, began, out)


Case = Callable[[Path], Outcome]
CASES: Final[dict[str, Case]] = {
    case.__name__: case
    for case in (
        spawned_workers_cannot_import_the_app,
        workers_by_hand_cannot_import_the_app,
        a_worker_with_another_key,
        more_processes_than_robots,
        a_thousand_processes,
        zero_processes,
        no_latency,
        an_objective_that_is_not_distributable,
        a_frozen_worker_on_virtual_time,
        a_frozen_worker_on_scaled_time,
        a_spawned_worker_killed_during_set_up,
        a_worker_by_hand_killed_during_set_up,
    )
}
CONFIGURATION: Final = frozenset({
    "spawned_workers_cannot_import_the_app",
    "workers_by_hand_cannot_import_the_app",
    "a_worker_with_another_key",
    "more_processes_than_robots",
    "a_thousand_processes",
    "zero_processes",
    "no_latency",
    "an_objective_that_is_not_distributable",
})  # fmt: skip
"""The cases that are the scenario's or the command line's fault: exit 2; the others 1."""
ARGPARSE: Final = frozenset({"zero_processes"})
"""Refused by the command line's parser, with its usage: nothing ran, nothing is written."""
WORKER_SIDE: Final = frozenset({"a_worker_with_another_key"})
"""The cases whose outcome is a refused worker's (it writes no results: it has no run)."""


@pytest.fixture(scope="module")
def outcome_of(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str], Outcome]:
    done: dict[str, Outcome] = {}

    def get(name: str) -> Outcome:
        if name not in done:
            done[name] = CASES[name](tmp_path_factory.mktemp(name))
        return done[name]

    return get


def said(stderr: str) -> list[str]:
    """The lines on stderr that are not progress lines."""
    return [line for line in stderr.splitlines() if line.strip() and not _PROGRESS.match(line)]


def _cases(*names: str, **xfails: str) -> list[Any]:
    """Parameters for these cases (all when none are named), some expected to fail."""
    return [
        pytest.param(name, marks=pytest.mark.xfail(strict=True, reason=xfails[name]))
        if name in xfails
        else name
        for name in (names or CASES)
    ]


LIMIT: Final = 120
FROZEN: Final = frozenset({"a_frozen_worker_on_virtual_time", "a_frozen_worker_on_scaled_time"})
"""The cases of a run that failed as it ran (exit 1, its summary on stdout)."""
START_UP: Final = frozenset(CASES) - FROZEN - ARGPARSE
"""The cases refused before the robots ran: one line on stderr, ``error: ...``."""


@pytest.mark.timeout(LIMIT)
@pytest.mark.parametrize("case", _cases())
def test_it_ends_with_the_right_exit_code(outcome_of: Callable[[str], Outcome], case: str) -> None:
    outcome = outcome_of(case)
    assert outcome.code is not None, f"still running after {GIVE_UP} s:\n{outcome.stderr}"
    assert outcome.code == (2 if case in CONFIGURATION else 1), outcome.stderr


@pytest.mark.timeout(LIMIT)
@pytest.mark.parametrize("case", _cases())
def test_it_ends_within_seconds(outcome_of: Callable[[str], Outcome], case: str) -> None:
    outcome = outcome_of(case)
    assert outcome.code is not None, f"still running after {GIVE_UP} s:\n{outcome.stderr}"
    limit = FAST + (WINDOW_LIMIT if case in FROZEN else 0.0)
    assert outcome.wall < limit, outcome.stderr


@pytest.mark.timeout(LIMIT)
@pytest.mark.parametrize("case", _cases(*sorted(START_UP)))
def test_a_start_up_failure_says_why_in_one_line(
    outcome_of: Callable[[str], Outcome], case: str
) -> None:
    outcome = outcome_of(case)
    assert "Traceback" not in outcome.stderr, outcome.stderr
    lines = said(outcome.stderr)
    assert len(lines) == 1, lines
    assert lines[0].startswith("error: "), lines


@pytest.mark.timeout(LIMIT)
@pytest.mark.parametrize(
    "case",
    _cases(*sorted(FROZEN)),
)
def test_a_failed_run_says_why_in_its_summary_without_a_traceback(
    outcome_of: Callable[[str], Outcome], case: str
) -> None:
    outcome = outcome_of(case)
    assert outcome.code == 1, outcome.stderr
    assert "FAILED" in outcome.stdout.splitlines()[0]
    assert re.search(r"(?m)^error +worker 1 is ", outcome.stdout), outcome.stdout
    assert "Traceback" not in outcome.stderr, outcome.stderr
    assert said(outcome.stderr) == [], outcome.stderr


@pytest.mark.timeout(LIMIT)
@pytest.mark.parametrize(
    "case",
    _cases(*sorted((START_UP | FROZEN) - WORKER_SIDE)),
)
def test_it_leaves_results_with_its_status_and_error(
    outcome_of: Callable[[str], Outcome], case: str
) -> None:
    outcome = outcome_of(case)
    assert outcome.results is not None, outcome.stderr
    assert outcome.results["status"] == "failed"
    error = outcome.results["error"]
    assert error
    # The error it said: on stderr (refused at start) or in its summary (failed as it ran).
    assert error in outcome.stderr or error in outcome.stdout


def test_zero_processes_is_a_usage_error(outcome_of: Callable[[str], Outcome]) -> None:
    outcome = outcome_of("zero_processes")
    assert outcome.code == 2
    assert "argument --processes: expected a whole number of at least 1, got '0'" in (
        outcome.stderr
    )


@pytest.mark.timeout(LIMIT)
@pytest.mark.parametrize(
    ("case", "reason"),
    [
        ("spawned_workers_cannot_import_the_app", "no driver for the robots on this host"),
        # Two workers that cannot import it: which of them says so first is a race.
        ("workers_by_hand_cannot_import_the_app",
         r'worker [01] refused the run: .*cannot import "local_app"'),
        ("a_worker_with_another_key", "signs with another key"),
        ("more_processes_than_robots", "6 worker processes for 5 robots: at most 5"),
        ("a_thousand_processes", "1000 worker processes for 25 robots: at most 25"),
        ("no_latency", "network.latency = 0 runs in one process only"),
        ("an_objective_that_is_not_distributable", "MoveObjects is not distributable"),
        ("a_spawned_worker_killed_during_set_up", "during set-up"),
        ("a_worker_by_hand_killed_during_set_up", "worker 0 is gone: its token went"),
    ],
)  # fmt: skip
def test_the_error_names_the_cause(
    outcome_of: Callable[[str], Outcome], case: str, reason: str
) -> None:
    outcome = outcome_of(case)
    assert re.search(reason, outcome.stderr), outcome.stderr


@pytest.mark.timeout(LIMIT)
@pytest.mark.parametrize("case", ["a_frozen_worker_on_virtual_time",
                                  "a_frozen_worker_on_scaled_time"])  # fmt: skip
def test_a_frozen_worker_is_named_with_its_robots_after_the_window_limit(
    outcome_of: Callable[[str], Outcome], case: str
) -> None:
    outcome = outcome_of(case)
    assert outcome.code == 1, outcome.stderr
    assert outcome.wall >= WINDOW_LIMIT  # not before it had its chance
    robots = outcome.facts["shares"][1]
    named = f"its {len(robots)} robots are lost: {', '.join(map(str, robots))}"
    assert "worker 1 is frozen or cut off" in outcome.stdout, outcome.stdout  # its summary
    assert outcome.results is not None
    assert "worker 1 is frozen or cut off" in outcome.results["error"]
    assert named in outcome.results["error"]
    # Continued at the end, it found its world gone and left.
    assert outcome.facts["frozen_code"] is not None, "the frozen worker still runs"


@pytest.mark.timeout(LIMIT)
def test_a_hand_started_worker_that_cannot_import_the_app_says_so_in_one_line(
    outcome_of: Callable[[str], Outcome],
) -> None:
    # The first worker welcomed refuses the run and the world ends it: the other one
    # refuses it too, or finds no world any more. Each says why in one line.
    outcome = outcome_of("workers_by_hand_cannot_import_the_app")
    assert 2 in outcome.facts["worker_codes"]
    assert set(outcome.facts["worker_codes"]) <= {1, 2}
    cannot_import = "app: cannot import \"local_app\": No module named 'local_app'"
    said_lines = [said(errors) for errors in outcome.facts["worker_errors"]]
    for lines in said_lines:
        assert len(lines) == 1, lines
        assert lines[0].startswith("error: ")
    assert any(cannot_import in lines[0] for lines in said_lines), said_lines


@pytest.mark.timeout(LIMIT)
def test_a_world_goes_on_waiting_after_a_hello_with_another_key_and_says_so(
    outcome_of: Callable[[str], Outcome],
) -> None:
    outcome = outcome_of("a_worker_with_another_key")
    assert outcome.facts["world_running"], "a hello with another key ended the run"
    assert "does not check against this world's key" in outcome.facts["world_said"]
