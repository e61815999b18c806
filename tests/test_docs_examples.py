"""The README's code and the examples run as documented (real subprocesses).

docs/testing.md's test file is run here too, as a user's project runs it (no conftest,
no settings); tests/test_docs_pages.py runs every other block of the pages.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.test_docs_pages import blocks

pytestmark = pytest.mark.slow  # the README's code in subprocesses, and mypy

ROOT = Path(__file__).resolve().parent.parent

pytest_plugins = ["pytester"]


def _run(args: list[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-X", "dev", "-W", "error", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=240,  # 46 s for the main job at a load of 8
        check=False,
    )


def test_readme_example_runs(tmp_path: Path) -> None:
    readme = (ROOT / "README.md").read_text()
    match = re.search(r"## Two robots exchanging messages\n\n```python\n(.*?)```", readme, re.S)
    assert match, "README lost its example"
    script = tmp_path / "readme_example.py"
    script.write_text(match.group(1))
    result = _run([str(script)])
    assert result.returncode == 0, result.stderr
    assert "robot 1 got Pong(10, 'thanks')" in result.stdout
    assert "robot 2 got Pong(20, 'thanks')" in result.stdout


def test_readme_example_type_checks_strictly(tmp_path: Path) -> None:
    pytest.importorskip("mypy", reason="mypy comes with the dev extra (CI installs it)")
    readme = (ROOT / "README.md").read_text()
    match = re.search(r"## Two robots exchanging messages\n\n```python\n(.*?)```", readme, re.S)
    assert match, "README lost its example"
    script = tmp_path / "readme_example.py"
    script.write_text(match.group(1))
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "mypy",
            "--strict",
            "--cache-dir",
            str(tmp_path / "cache"),
            "--config-file",
            str(ROOT / "pyproject.toml"),
            str(script),
        ],
        cwd=tmp_path,
        env={**os.environ, "MYPYPATH": str(ROOT)},  # an editable install hides it from mypy
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr


def test_two_robots_example_runs() -> None:
    result = _run(["examples/two_robots.py", "--throws", "4", "--time-factor", "200"])
    assert result.returncode == 0, result.stderr
    assert "robot 1 caught throw 4" in result.stdout
    assert "4 throws in" in result.stdout


def test_readme_main_job_runs_as_written(tmp_path: Path) -> None:
    """The set-up's first command, run as the README says (output redirected to tmp_path)."""
    readme = (ROOT / "README.md").read_text()
    match = re.search(r"&& python -m cas_async run (\S+)", readme)
    assert match, "README lost its main job"
    scenario = match.group(1)
    assert (ROOT / scenario).is_file()
    result = _run(["-m", "cas_async", "run", scenario, "--out", str(tmp_path)])
    assert result.returncode == 0, result.stderr
    assert "20 of 20" in result.stdout
    assert "completed" in result.stdout
    assert {p.name for p in tmp_path.iterdir()} >= {"results.json", "trace.csv"}


def test_the_getting_started_page_shows_the_readme_s_set_up() -> None:
    """The page shows the two commands as text; the README's are run above."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    match = re.search(r"## Set-up\n.*?```sh\n(.*?)```", readme, re.S)
    assert match, "README lost its set-up"
    page = (ROOT / "docs" / "getting-started.md").read_text(encoding="utf-8")
    assert f"```text\n{match.group(1)}```" in page


def test_the_testing_page_s_example_passes_in_a_project_without_conftest(
    pytester: pytest.Pytester,
) -> None:
    """What a user's project that only installed cas_async gets: no conftest, no settings."""
    (block,) = [b for b in blocks(ROOT / "docs" / "testing.md") if b.title == "test_echo.py"]
    pytester.makepyfile(test_readme=block.text)
    result = pytester.runpytest_subprocess("-p", "no:cacheprovider", "-v", "--durations=0")
    result.assert_outcomes(passed=2)
    result.stdout.fnmatch_lines(["*test_an_hour_of_beacons PASSED*"])
