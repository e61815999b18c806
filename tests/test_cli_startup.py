"""Start-up refusals of ``python -m cas_async run``: one line on stderr, exit code 2.

Whatever stops a run before its robots run (the scenario, the app's build, the
machinery a flag needs, a start refused) is a configuration error: the command
line says what is wrong in one ``error: ...`` line and exits 2, as for a wrong
scenario key. Exit 1 stays for runs that failed. Real subprocesses, as a user
runs them.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Final

import pytest

from tests.test_cli import ROOT, RUN_LIMIT, Finished, run_cli

GATHERING: Final = ROOT / "examples" / "gathering" / "gathering.toml"
BOX_MOVING: Final = ROOT / "apps" / "box_moving" / "scenarios" / "thesis_4_4.toml"
EXIT_USAGE: Final = 2


def refused_in_one_line(finished: Finished) -> str:
    """The one line a refused run printed on stderr (and checks that it was refused so)."""
    assert finished.code == EXIT_USAGE, finished.stderr
    assert "Traceback" not in finished.stderr, finished.stderr
    lines = finished.stderr.splitlines()
    assert len(lines) == 1, finished.stderr
    assert lines[0].startswith("error: ")
    assert finished.stdout == ""
    return lines[0]


def assert_failed_with(out: Path, line: str) -> None:
    """The run's results.json says it failed, with the error the line said."""
    results = json.loads((out / "results.json").read_text(encoding="utf-8"))
    assert results["status"] == "failed"
    assert line == f"error: {results['error']}"


def scenario(tmp_path: Path, app: str, run: str = "") -> Path:
    path = tmp_path / "refused.toml"
    path.write_text(f'app = "{app}"\n[run]\n{run}\n[world]\nwidth = 10\nheight = 10\n')
    return path


def test_an_objective_that_cannot_run_across_processes_says_what_distributable_means(
    tmp_path: Path,
) -> None:
    pytest.importorskip("zenoh", reason="--processes needs the zenoh extra: it says so first")
    line = refused_in_one_line(
        run_cli("run", BOX_MOVING, "--processes", "2", "--out", tmp_path / "out")
    )
    # Box Moving's objective reads the robots' layers (the tutorial's Gathered no longer does).
    assert "--processes: Box Moving's objective MoveObjects is not distributable" in line
    assert "the world process observes a mirror of their Environment" in line
    assert "set distributable = True on MoveObjects" in line
    assert "Otherwise run without --processes" in line
    assert_failed_with(tmp_path / "out", line)


def test_processes_without_the_zenoh_extra_say_how_to_install_it(tmp_path: Path) -> None:
    # The process sees no zenoh module, as where the extra is not installed.
    without_zenoh = (
        "import sys; sys.modules['zenoh'] = None; "
        "from cas_async._cli._main import main; sys.exit(main(sys.argv[1:], owns_process=True))"
    )
    completed = subprocess.run(
        [
            sys.executable,
            "-c",
            without_zenoh,
            "run",
            str(GATHERING),
            "--processes",
            "2",
            "--out",
            str(tmp_path / "out"),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=RUN_LIMIT,
        check=False,
    )
    line = refused_in_one_line(Finished(completed.returncode, completed.stdout, completed.stderr))
    assert line == (
        "error: --processes runs the robots in worker processes that talk over Zenoh: "
        'the Zenoh transport needs eclipse-zenoh: pip install "cas_async[zenoh]"'
    )


def test_an_app_that_refuses_to_build_is_a_configuration_error(tmp_path: Path) -> None:
    path = scenario(tmp_path, "tests.startup_apps:refuses_to_build", "virtual = true")
    line = refused_in_one_line(run_cli("run", path, "--out", tmp_path / "out"))
    assert line == "error: robots.count: this app builds at most 1 robot on Tuesdays"


def test_a_start_refused_by_the_clock_is_a_configuration_error(tmp_path: Path) -> None:
    path = scenario(
        tmp_path, "tests.startup_apps:own_clock", 'transport = "memory"\ntime_factor = 100'
    )
    line = refused_in_one_line(run_cli("run", path, "--out", tmp_path / "out"))
    assert "VirtualClock needs the virtual-time event loop" in line
    assert_failed_with(tmp_path / "out", line)


def test_virtual_time_over_zenoh_without_processes_is_refused(tmp_path: Path) -> None:
    pytest.importorskip("zenoh", reason="the zenoh extra")
    path = scenario(
        tmp_path, "tests.startup_apps:refuses_to_build", 'virtual = true\ntransport = "zenoh"'
    )
    line = refused_in_one_line(run_cli("run", path, "--out", tmp_path / "out"))
    assert "virtual time over Zenoh needs processes that share it" in line
