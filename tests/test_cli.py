"""``python -m cas_async run``, exercised as a user runs it: a real subprocess.

Each test starts the command line in the repository root (where ``apps`` and
``tests`` import as they do for someone working there) and checks its exit code,
what it printed and the files it wrote. Every wait has a time limit, and a
process still running when a test ends is killed.
"""

from __future__ import annotations

import csv
import io
import json
import os
import re
import selectors
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import pytest

pytestmark = pytest.mark.slow  # every test runs the command line in a subprocess (1-3 s each)

ROOT: Final = Path(__file__).resolve().parents[1]
SCENARIOS: Final = ROOT / "apps" / "fire_brigade" / "scenarios"
SHIPPED: Final = SCENARIOS / "thesis_5_8_1.toml"
LONG: Final = SCENARIOS / "thesis_5_8_2.toml"
"""25 robots at speed 3: about 230 simulated seconds, so long on scaled real time."""

FAST: Final = ("--virtual", "--set", "mission.buckets=5")
PLOTS: Final = (
    "initial_positions.png",
    "snapshots_by_exchange.png",
    "snapshots_by_time.png",
    "trajectories.png",
    "over_time.png",
)
PNG_MAGIC: Final = b"\x89PNG\r\n\x1a\n"
TRACE_HEADER: Final = "t,robot,x,y,exchange,carrying"

RUN_LIMIT: Final = 60.0
"""Wall seconds any run may take; only a hung one comes near (the longest takes ~3 s)."""
STOP_LIMIT: Final = 10.0
"""Wall seconds a run may take to stop and write its results after a signal."""

_ENV: Final = {**os.environ, "PYTHONIOENCODING": "utf-8"}  # the summary has an em dash


@dataclass(frozen=True)
class Finished:
    """A command-line run that ended: its exit code and everything it printed."""

    code: int
    stdout: str
    stderr: str


def start_cli(*args: str | os.PathLike[str]) -> subprocess.Popen[str]:
    """``python -m cas_async *args`` in the repository root, output piped; use it in ``with``."""
    return subprocess.Popen(
        [sys.executable, "-m", "cas_async", *map(str, args)],
        cwd=ROOT,
        env=_ENV,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        encoding="utf-8",
    )


def run_cli(*args: str | os.PathLike[str], limit: float = RUN_LIMIT) -> Finished:
    """Runs ``python -m cas_async *args`` to its end; fails the test after ``limit`` seconds."""
    with start_cli(*args) as process:
        try:
            stdout, stderr = process.communicate(timeout=limit)
        except subprocess.TimeoutExpired:
            process.kill()
            _, stderr = process.communicate(timeout=STOP_LIMIT)
            pytest.fail(f"still running after {limit} s: {args}\nstderr:\n{stderr}")
        finally:
            process.kill()  # nothing when it has exited; the only way out otherwise
    return Finished(process.returncode, stdout, stderr)


def read_results(out: Path) -> dict[str, Any]:
    data = json.loads((out / "results.json").read_text(encoding="utf-8"))
    assert isinstance(data, dict)
    return data


def _first_line(process: subprocess.Popen[str], limit: float) -> str:
    """What the process wrote to stderr up to its first line break, within ``limit`` seconds.

    Reads the pipe's file descriptor directly (never its buffered text wrapper), so
    ``communicate`` later picks up exactly where this stopped; any text after the
    first line break is returned too.
    """
    assert process.stderr is not None
    fd = process.stderr.fileno()
    deadline = time.monotonic() + limit
    received = b""
    with selectors.DefaultSelector() as selector:
        selector.register(fd, selectors.EVENT_READ)
        while b"\n" not in received:
            left = deadline - time.monotonic()
            if left <= 0 or not selector.select(left):
                pytest.fail(f"no line on stderr within {limit} s; got {received!r}")
            chunk = os.read(fd, 65536)
            if not chunk:
                pytest.fail(f"stderr closed before a full line; got {received!r}")
            received += chunk
    return received.decode("utf-8")


def _summary_value(stdout: str, label: str) -> str:
    """The text after ``label`` on its summary table row."""
    row = re.search(rf"^{re.escape(label)}\s+(.*)$", stdout, re.MULTILINE)
    assert row is not None, f"no {label!r} row in:\n{stdout}"
    return row.group(1)


# -- a complete run on virtual time --------------------------------------------------------


@pytest.fixture(scope="module")
def virtual_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Finished, Path]:
    """One fast virtual-time run with figures, shared by the tests that only read it."""
    out = tmp_path_factory.mktemp("virtual") / "out"
    return run_cli("run", SHIPPED, *FAST, "--seed", "3", "--out", out), out


def test_a_completed_run_exits_0_and_prints_the_summary(virtual_run: tuple[Finished, Path]) -> None:
    finished, out = virtual_run
    assert finished.code == 0, finished.stderr
    header = finished.stdout.splitlines()[0]
    assert header.startswith("Fire Brigade")
    assert header.endswith("seed 3: completed")
    results = read_results(out)
    makespan = _summary_value(finished.stdout, "makespan")
    assert makespan.startswith(f"{results['makespan']:,.1f} s simulated")
    assert _summary_value(finished.stdout, "buckets delivered").startswith("5 of 5 ")
    assert f"to {out}/" in finished.stdout.splitlines()[-1]
    assert "Traceback" not in finished.stderr


def test_results_json_records_the_outcome_the_seed_and_the_configuration(
    virtual_run: tuple[Finished, Path],
) -> None:
    _, out = virtual_run
    results = read_results(out)
    assert (results["status"], results["error"]) == ("completed", None)
    assert (results["target"], results["delivered"]) == (5, 5)
    assert results["makespan"] == results["sim_time"] > 0
    assert results["seed"] == 3
    config = results["config"]
    assert config["mission"]["buckets"] == 5  # the --set override
    assert config["run"]["seed"] == 3  # --seed
    assert (config["run"]["virtual"], config["run"]["transport"]) == (True, "memory")
    assert config["app"] == "apps.fire_brigade"
    assert results["statistics"]["travel_time"]["count"] == 5
    assert results["statistics"]["messages"]["external"] > 0


def test_trace_csv_has_every_robot_and_every_exchange(virtual_run: tuple[Finished, Path]) -> None:
    _, out = virtual_run
    results = read_results(out)
    with (out / "trace.csv").open(newline="", encoding="utf-8") as stream:
        assert stream.readline().rstrip("\r\n") == TRACE_HEADER
        rows = list(csv.reader(stream))
    robots = {robot for group in results["groups"].values() for robot in group}
    assert {int(row[1]) for row in rows if float(row[0]) == 0.0} == robots == set(range(1, 21))
    exchanges = {int(row[4]) for row in rows if row[4]}
    assert exchanges == set(range(1, results["exchanges"] + 1))


def test_the_five_figures_are_png_files(virtual_run: tuple[Finished, Path]) -> None:
    finished, out = virtual_run
    assert sorted(path.name for path in out.glob("*.png")) == sorted(PLOTS)
    for name in PLOTS:
        assert (out / name).read_bytes().startswith(PNG_MAGIC), name
        assert name in finished.stdout.splitlines()[-1]  # the "wrote ..." line


def test_no_plots_writes_no_figure_and_the_same_run_again(
    virtual_run: tuple[Finished, Path], tmp_path: Path
) -> None:
    out = tmp_path / "out"
    finished = run_cli("run", SHIPPED, *FAST, "--seed", "3", "--out", out, "--no-plots")
    assert finished.code == 0, finished.stderr
    assert sorted(path.name for path in out.iterdir()) == [
        "results.json",
        "scene.json",
        "trace.csv",
    ]
    assert ".png" not in finished.stdout
    # Virtual time is deterministic: same seed, same run (the wall time aside).
    _, first_out = virtual_run
    first, again = read_results(first_out), read_results(out)
    del first["wall_time"], again["wall_time"]
    assert again == first
    assert (out / "trace.csv").read_bytes() == (first_out / "trace.csv").read_bytes()


# -- a wrong command line or scenario: exit code 2, nothing run or written --------------------

_UNKNOWN_KEY_TOML = """\
app = "apps.fire_brigade"

[world]
width = 10.0
height = 10.0

[transporters]
count = 4
colour = "red"
"""


def _shipped(tmp_path: Path) -> Path:
    return SHIPPED


def _with_unknown_key(tmp_path: Path) -> Path:
    # Written in full: ``extends`` is relative to the file, and this file is not
    # beside the shipped ones.
    path = tmp_path / "unknown_key.toml"
    path.write_text(_UNKNOWN_KEY_TOML, encoding="utf-8")
    return path


def _not_toml(tmp_path: Path) -> Path:
    path = tmp_path / "broken.toml"
    path.write_text('app = "apps.fire_brigade"\n[world\n', encoding="utf-8")
    return path


def _missing(tmp_path: Path) -> Path:
    return tmp_path / "missing.toml"


@pytest.mark.parametrize(
    ("scenario", "args", "key"),
    [
        pytest.param(_with_unknown_key, [], "transporters: unknown key 'colour'", id="unknown-key"),
        pytest.param(
            _shipped, ["--set", "transporters.speed=-1"], "transporters.speed", id="negative-speed"
        ),
        pytest.param(
            _shipped,
            ["--set", "stations.generators=[[40.0, 0.0]]"],
            "stations.generators[0]",
            id="generator-outside-the-world",
        ),
        pytest.param(_shipped, ["--set", "strategy.name=nope"], "strategy.name", id="strategy"),
        pytest.param(
            _shipped,
            ["--set", "strategy.name=tests.fire_brigade.nowhere:Nearest"],
            "strategy.name",
            id="strategy-path-that-does-not-import",
        ),
        pytest.param(
            _shipped, ["--virtual", "--transport", "udp"], "run.transport", id="virtual-with-udp"
        ),
        pytest.param(_shipped, ["--time-factor", "0"], "run.time_factor", id="time-factor-0"),
        pytest.param(_shipped, ["--seed", "-1"], "run.seed", id="negative-seed"),
        pytest.param(_shipped, ["--set", "mission.buckets"], "--set", id="set-without-value"),
        # Absurd sizes fail before anything is built (they used to build until memory ran out).
        pytest.param(
            _shipped, ["--set", "transporters.count=1000000000000"], "transporters.count", id="1e12"
        ),
        pytest.param(
            _shipped,
            ["--virtual", "--set", "transporters.count=99999999999999999999999"],
            "transporters.count",
            id="1e23-in-memory",
        ),
        pytest.param(
            _shipped, ["--set", "stations.repeat=1000000000000000000"], "stations.repeat", id="1e18"
        ),
        pytest.param(
            _shipped, ["--set", "run.trace_interval=1e-300"], "run.trace_interval", id="trace-1e300"
        ),
        pytest.param(_missing, [], "no such file", id="missing-file"),
        pytest.param(_not_toml, [], "not valid TOML", id="not-toml"),
    ],
)
def test_a_wrong_scenario_exits_2_naming_the_file_and_the_key(
    scenario: Any, args: list[str], key: str, tmp_path: Path
) -> None:
    path = scenario(tmp_path)
    out = tmp_path / "out"
    finished = run_cli("run", path, *args, "--out", out)
    assert finished.code == 2, finished.stdout + finished.stderr
    assert finished.stderr.startswith(f"error: {path}: {key}"), finished.stderr
    assert "Traceback" not in finished.stderr
    assert finished.stdout == ""
    assert not out.exists()


@pytest.mark.parametrize(
    ("args", "complaint"),
    [
        pytest.param([], "required: COMMAND", id="no-command"),
        pytest.param(["run"], "required: scenario", id="no-scenario"),
        pytest.param(["fly", "x.toml"], "invalid choice: 'fly'", id="unknown-command"),
        pytest.param(
            ["run", str(SHIPPED), "--virtual", "--time-factor", "3"],
            "not allowed with argument --virtual",
            id="virtual-and-time-factor",
        ),
        pytest.param(
            ["run", str(SHIPPED), "--transport", "tcp"], "invalid choice: 'tcp'", id="transport"
        ),
        pytest.param(["run", str(SHIPPED), "--seed", "one"], "--seed", id="seed-not-a-number"),
    ],
)
def test_a_wrong_command_line_exits_2_with_the_usage(
    args: list[str], complaint: str, tmp_path: Path
) -> None:
    finished = run_cli(*args, "--out", tmp_path / "out") if args else run_cli()
    assert finished.code == 2, finished.stderr
    assert finished.stderr.startswith("usage: python -m cas_async")
    assert complaint in finished.stderr
    assert finished.stdout == ""
    assert not (tmp_path / "out").exists()


# -- runs that end without the target -------------------------------------------------------


def test_running_out_of_simulated_time_exits_1_with_status_timed_out(tmp_path: Path) -> None:
    out = tmp_path / "out"
    finished = run_cli(
        "run", SHIPPED, "--virtual", "--set", "run.max_time=2", "--no-plots", "--out", out
    )
    assert finished.code == 1, finished.stderr
    results = read_results(out)
    assert results["status"] == "timed_out"
    assert results["makespan"] is None
    assert results["sim_time"] == pytest.approx(2.0)
    assert results["delivered"] < results["target"] == 20
    assert "TIMED OUT" in finished.stdout.splitlines()[0]
    assert _summary_value(finished.stdout, "makespan").startswith("not reached")


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals and pipes")
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_stops_the_run_with_130_and_still_writes_the_results(
    signum: signal.Signals, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    # About two wall minutes at this factor: the signal always lands mid-run.
    args = ("--time-factor", "2", "--transport", "memory", "--set", "run.progress_interval=0.2")
    with start_cli("run", LONG, *args, "--no-plots", "--out", out) as process:
        try:
            # Not a TTY: plain progress lines; the first one means the run is under way.
            progress = _first_line(process, RUN_LIMIT)
            assert re.match(r"t=\d+\.\ds buckets \d+/20 exchanges \d+\n", progress), progress
            process.send_signal(signum)
            stdout, stderr = process.communicate(timeout=STOP_LIMIT)
        finally:
            process.kill()
    assert process.returncode == 130, progress + stderr
    assert "Traceback" not in stderr
    results = read_results(out)
    assert results["status"] == "interrupted"
    assert results["makespan"] is None
    assert results["delivered"] < results["target"] == 20
    assert results["config"]["run"]["time_factor"] == 2.0
    assert "INTERRUPTED" in stdout.splitlines()[0]
    assert _summary_value(stdout, "buckets delivered").endswith(")")  # the whole table
    assert (out / "trace.csv").read_text(encoding="utf-8").startswith(TRACE_HEADER + "\n")


def _catches(pid: int, signum: int) -> bool:
    """Whether process ``pid`` has a handler for ``signum`` (Linux: SigCgt in /proc)."""
    for line in Path(f"/proc/{pid}/status").read_text(encoding="ascii").splitlines():
        if line.startswith("SigCgt:"):
            return bool(int(line.split()[1], 16) >> (signum - 1) & 1)
    return False


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads /proc")
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_while_importing_exits_130_quietly(signum: signal.Signals, tmp_path: Path) -> None:
    # Python catches SIGINT from the start, SIGTERM only once cas_async's first line ran:
    # from then on (the imports take a few tenths of a second) a signal exits 130.
    out = tmp_path / "out"
    with start_cli("run", SHIPPED, "--out", out) as process:
        try:
            deadline = time.monotonic() + RUN_LIMIT
            while not _catches(process.pid, signal.SIGTERM):
                assert process.poll() is None, "exited before the signal"
                assert time.monotonic() < deadline, "SIGTERM never handled"
                time.sleep(0.001)
            process.send_signal(signum)
            stdout, stderr = process.communicate(timeout=STOP_LIMIT)
        finally:
            process.kill()
    assert process.returncode == 130, stderr
    assert (stdout, stderr) == ("", "")  # no KeyboardInterrupt traceback
    assert not (out / "results.json").exists()  # nothing had begun


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals and pipes")
def test_a_signal_while_building_abandons_the_build(tmp_path: Path) -> None:
    scenario = tmp_path / "slow.toml"
    scenario.write_text(
        'app = "tests.scenario.fake_app:slow_build"\n[world]\nwidth = 1\nheight = 1\n',
        encoding="utf-8",
    )
    out = tmp_path / "out"
    with start_cli("run", scenario, "--out", out) as process:
        try:
            assert _first_line(process, RUN_LIMIT) == "building\n"  # a minute of it
            process.send_signal(signal.SIGTERM)
            stdout, stderr = process.communicate(timeout=STOP_LIMIT)
        finally:
            process.kill()
    assert process.returncode == 130, stderr
    assert stderr == "interrupted while building the robots: nothing ran\n"
    assert stdout == f"wrote results.json to {out}/\n"
    assert [path.name for path in out.iterdir()] == ["results.json"]
    results = read_results(out)
    assert (results["status"], results["sim_time"], results["delivered"]) == (
        "interrupted",
        0.0,
        0,
    )
    assert 0 < results["wall_time"] < RUN_LIMIT


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_a_signal_while_drawing_leaves_whole_files_only(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with start_cli("run", SHIPPED, *FAST, "--out", out) as process:
        try:
            # The results are written as soon as the run ends; the figures come next.
            deadline = time.monotonic() + RUN_LIMIT
            while not (out / "results.json").exists():
                assert process.poll() is None, process.communicate()
                assert time.monotonic() < deadline, "no results.json"
                time.sleep(0.005)
            process.send_signal(signal.SIGINT)
            stdout, stderr = process.communicate(timeout=STOP_LIMIT)
        finally:
            process.kill()
    assert process.returncode == 130, stderr
    assert read_results(out)["status"] == "completed"
    assert "wrote results.json, trace.csv" in stdout
    assert "interrupted: figures not drawn" in stderr
    assert "Traceback" not in stderr
    for path in out.iterdir():
        assert not path.name.startswith("."), f"a temporary file was left: {path.name}"
        if path.suffix == ".png":  # drawn before the signal: whole
            assert path.read_bytes().startswith(PNG_MAGIC)
            assert path.read_bytes().endswith(b"IEND\xaeB`\x82")


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_in_process_a_signal_stops_the_run_and_main_returns_130(tmp_path: Path) -> None:
    # Not `python -m cas_async`: the robots are stopped one by one, nothing exits early.
    from cas_async._cli._main import main

    out = tmp_path / "out"
    stdout, stderr = io.StringIO(), io.StringIO()
    timer = threading.Timer(1.0, os.kill, (os.getpid(), signal.SIGINT))
    before = signal.getsignal(signal.SIGINT)
    timer.start()
    try:
        code = main(
            ["run", str(LONG), "--time-factor", "2", "--transport", "memory", "--no-plots",
             "--out", str(out)],
            stdout=stdout,
            stderr=stderr,
        )  # fmt: skip
    finally:
        timer.cancel()
    assert code == 130, stderr.getvalue()
    assert signal.getsignal(signal.SIGINT) is before
    results = read_results(out)
    assert results["status"] == "interrupted"
    assert 0 < results["sim_time"] < 60
    assert "INTERRUPTED" in stdout.getvalue().splitlines()[0]


# -- a strategy of one's own ----------------------------------------------------------------


def test_a_strategy_named_by_its_import_path_runs(tmp_path: Path) -> None:
    name = "tests.fire_brigade.nearest:NearestFirst"
    out = tmp_path / "out"
    finished = run_cli(
        "run", SHIPPED, *FAST, "--set", f"strategy.name={name}", "--no-plots", "--out", out
    )
    assert finished.code == 0, finished.stdout + finished.stderr
    results = read_results(out)
    assert (results["status"], results["delivered"]) == ("completed", 5)
    assert results["extra"]["strategy"] == name
    assert _summary_value(finished.stdout, "strategy") == name


def test_an_unusable_out_directory_is_refused_before_the_run(tmp_path: Path) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("not a directory\n")
    finished = run_cli("run", SHIPPED, *FAST, "--out", blocker / "out")
    assert finished.code == 2
    assert finished.stderr.startswith(f"error: --out {blocker / 'out'}:")
    assert finished.stdout == ""  # nothing ran


def test_result_files_get_the_usual_permissions(virtual_run: tuple[Finished, Path]) -> None:
    _, out = virtual_run
    umask = os.umask(0)
    os.umask(umask)
    for name in ("results.json", "trace.csv"):
        assert (out / name).stat().st_mode & 0o777 == 0o666 & ~umask


# -- a layer that fails, with and without restarts -------------------------------------------

CRASHING: Final = "strategy.name=tests.fire_brigade.crashing:CrashOnce"


def test_a_failing_layer_fails_the_run_with_exit_1_and_results(tmp_path: Path) -> None:
    out = tmp_path / "out"
    finished = run_cli("run", SHIPPED, *FAST, "--set", CRASHING, "--no-plots", "--out", out)
    assert finished.code == 1, finished.stdout + finished.stderr
    results = read_results(out)
    assert results["status"] == "failed"
    assert "layer 1 (CrashOnce) failed: RuntimeError" in results["error"]
    assert "the strategy broke down" in results["traceback"]
    assert "Traceback (most recent call last)" in finished.stderr
    assert "in choose" in finished.stderr  # the traceback reaches the raising line


def test_with_restarts_a_failing_layer_is_restarted_and_the_run_completes(tmp_path: Path) -> None:
    out = tmp_path / "out"
    finished = run_cli(
        "run", SHIPPED, *FAST, "--set", CRASHING, "--set", "run.restarts=1", "--no-plots",
        "--out", out,
    )  # fmt: skip
    assert finished.code == 0, finished.stdout + finished.stderr
    assert read_results(out)["status"] == "completed"
    assert "failed, restarting (restart 1 of 1 allowed within 60 s)" in finished.stderr


# -- the swarm key ---------------------------------------------------------------------------


def test_a_key_file_signs_every_datagram_of_a_udp_run(tmp_path: Path) -> None:
    key_file = tmp_path / "swarm.key"
    key_file.write_text("ab" * 32 + "\n")
    key_file.chmod(0o600)
    out = tmp_path / "out"
    finished = run_cli(
        "run", SHIPPED, "--set", "mission.buckets=2", "--time-factor", "50", "--no-plots",
        "--key-file", key_file, "--out", out,
    )  # fmt: skip
    assert finished.code == 0, finished.stdout + finished.stderr
    dropped = read_results(out)["protocol_errors"]
    # Requests re-sent under load are routine duplicates; nothing may be refused.
    assert set(dropped) <= {"duplicate"}, dropped


def test_an_unusable_key_file_is_refused_before_the_run(tmp_path: Path) -> None:
    key_file = tmp_path / "short.key"
    key_file.write_text("abcd\n")
    key_file.chmod(0o600)
    finished = run_cli("run", SHIPPED, *FAST, "--key-file", key_file, "--out", tmp_path / "o")
    assert finished.code == 2
    assert finished.stderr.startswith("error:")
    assert str(key_file) in finished.stderr
    assert finished.stdout == ""


def test_a_key_with_objects_passed_is_refused_before_the_run(tmp_path: Path) -> None:
    key_file = tmp_path / "swarm.key"
    key_file.write_text("ab" * 32 + "\n")
    key_file.chmod(0o600)
    args = ("--set", "run.pass_objects=true", "--key-file", key_file, "--out", tmp_path / "o")
    finished = run_cli("run", SHIPPED, *FAST, *args)
    assert finished.code == 2
    assert finished.stderr.startswith(f"error: {SHIPPED}: run.pass_objects"), finished.stderr
    assert not (tmp_path / "o").exists()
