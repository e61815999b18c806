"""Figures the pages state about this repository, held within a tolerance by measuring them.

A page may say "about 3,200 tests": the figure is rounded on purpose, so that it
holds while the suite grows a little, and this test says when it no longer does.
Output a page shows as a command's own is checked exactly, by running the command
(``tests/test_docs_pages.py``).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path
from typing import Final

import pytest

ROOT: Final = Path(__file__).resolve().parents[1]
TESTING: Final = ROOT / "docs" / "testing.md"
TOLERANCE: Final = 0.1
"""How far a stated count may be from the measured one, as a fraction of the measured."""
STATED: Final = re.compile(
    r"The suite has about ([\d,]+) tests, about ([\d,]+) of them marked\s+`slow`"
)
COLLECTED: Final = re.compile(r"^(\d+)/(\d+) tests collected", re.M)


def stated_counts() -> tuple[int, int]:
    """The whole suite's and the slow tests' counts, as docs/testing.md states them."""
    found = STATED.search(TESTING.read_text(encoding="utf-8"))
    assert found, "docs/testing.md no longer says 'The suite has about N tests, about M ...'"
    whole, slow = (int(figure.replace(",", "")) for figure in found.groups())
    return whole, slow


@pytest.mark.slow  # collects the whole suite in a subprocess
@pytest.mark.timeout(300)
def test_the_testing_page_counts_the_suite_within_a_tenth() -> None:
    stated_whole, stated_slow = stated_counts()
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider",
         "-m", "slow"],
        cwd=ROOT, capture_output=True, text=True, timeout=240, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    if "SKIPPED [" in done.stdout:  # modules of an extra not installed here are not counted
        pytest.skip("the page counts the suite with every extra installed (the dev extra)")
    collected = COLLECTED.search(done.stdout)
    assert collected, done.stdout[-2000:]
    slow, whole = (int(n) for n in collected.groups())
    assert abs(stated_whole - whole) <= TOLERANCE * whole, (
        f"docs/testing.md says about {stated_whole:,} tests; the suite has {whole:,}"
    )
    assert abs(stated_slow - slow) <= TOLERANCE * slow, (
        f"docs/testing.md says about {stated_slow:,} slow tests; the suite has {slow:,}"
    )
