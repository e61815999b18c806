"""docs/rl.md's code runs, and the commands it shows without their output work.

The commands run as a user runs them (real subprocesses, warnings as errors), shortened.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.test_docs_pages import blocks

pytest.importorskip("pettingzoo")

ROOT = Path(__file__).resolve().parent.parent.parent
DOC = ROOT / "docs" / "rl.md"


def run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-X", "dev", "-W", "error", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=240,  # a loaded machine's wall time (dev mode makes asyncio slower too)
        check=False,
    )


def test_the_quick_start_runs_with_warnings_as_errors(tmp_path: Path) -> None:
    """tests/test_docs_pages.py runs the page's commands; this, the quick start under -W error."""
    (block,) = [b for b in blocks(DOC) if b.title == "quick_start.py"]
    script = tmp_path / "quick_start.py"
    script.write_text(f"import sys\nsys.path.insert(0, {str(ROOT)!r})\n" + block.text)
    result = run(str(script))
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "timed_out None"


@pytest.mark.slow
def test_the_baselines_run() -> None:
    gathering = run("-m", "examples.rl.gathering.baseline", "--episodes", "2")
    assert gathering.returncode == 0, gathering.stderr
    assert re.search(r"^random +mean return +-?\d+\.\d\d +completed \d/2", gathering.stdout, re.M)
    brigade = run("-m", "examples.rl.fire_brigade.baseline", "--episodes", "1")
    assert brigade.returncode == 0, brigade.stderr
    assert "time strategy mean return" in brigade.stdout


@pytest.mark.slow
def test_the_training_command_writes_its_curve_and_its_figures(tmp_path: Path) -> None:
    out = tmp_path / "training"
    result = run(
        "-m", "examples.rl.gathering.train", "--episodes", "4", "--eval-every", "2",
        "--eval-episodes", "2", "--out", str(out),
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert (out / "learning_curve.png").stat().st_size > 10_000
    record = json.loads((out / "training.json").read_text())
    assert record["episodes"] == 4
    assert [episode for episode, _ in record["evaluations"]] == [0, 2, 4]
    assert record["random_completed"] == 0
    assert "4 episodes" in result.stdout
