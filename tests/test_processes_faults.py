"""``[faults]`` across processes: the wire loses datagrams between and inside workers too.

The Fire Brigade of §5.8.2 at ``faults.loss = 0.3`` on virtual time, in one process
and across two (issue 29: the loss used to be ignored silently across processes,
``results.json`` saying ``faults: null``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Final

import pytest

from tests.processes_support import SCENARIO, assert_all_delivered, read_results, run_cli

pytestmark = pytest.mark.slow  # lossy runs, one of them in three processes

pytest.importorskip("zenoh")

LOSSY: Final = ("--virtual", "--set", "faults.loss=0.3", "--no-plots")
LIMIT: Final = 240


@dataclass(frozen=True)
class Lossy:
    trace: bytes
    results: dict[str, Any]


@pytest.fixture(scope="module")
def lossy(tmp_path_factory: pytest.TempPathFactory) -> dict[int, Lossy]:
    """The lossy run in one process (1) and in two (2)."""
    runs = {}
    for processes in (1, 2):
        tmp = tmp_path_factory.mktemp(f"lossy{processes}")
        spread = ("--processes", str(processes)) if processes > 1 else ()
        finished = run_cli(tmp / "logs", "run", SCENARIO, *LOSSY, *spread, "--out", tmp / "out",
                           limit=120.0)  # fmt: skip
        assert finished.code == 0, finished.output
        assert not finished.left_behind, "a worker outlived the run"
        runs[processes] = Lossy((tmp / "out" / "trace.csv").read_bytes(), read_results(tmp / "out"))
    return runs


@pytest.mark.timeout(LIMIT)
def test_a_lossy_run_across_processes_delivers_every_bucket_as_slowly_as_in_one(
    lossy: dict[int, Lossy],
) -> None:
    alone, spread = lossy[1].results, lossy[2].results
    assert_all_delivered(alone)
    assert_all_delivered(spread)
    clean = 24.0  # thesis_5_8_2, seed 1, virtual, no loss: 23.9 s
    assert alone["makespan"] > 1.5 * clean  # the loss costs in one process...
    assert spread["makespan"] > 1.5 * clean  # ...and across processes: it is applied
    assert spread["makespan"] == pytest.approx(alone["makespan"], rel=0.25)
    assert spread["protocol_errors"]["duplicate"] > 0  # resent requests, answered twice


@pytest.mark.timeout(LIMIT)
def test_the_results_say_what_the_wire_lost_across_processes(lossy: dict[int, Lossy]) -> None:
    alone, spread = lossy[1].results["faults"], lossy[2].results["faults"]
    assert alone["lost"] > 0
    assert spread is not None
    assert spread["lost"] == pytest.approx(alone["lost"], rel=0.25)
    assert spread["sent"] == pytest.approx(alone["sent"], rel=0.25)


@pytest.mark.timeout(LIMIT)
def test_a_lossy_run_is_the_same_in_two_processes_as_in_one(lossy: dict[int, Lossy]) -> None:
    """Each robot draws its faults from a generator of its own, in the order of its own sends.

    That order is the same in any partition once the loop runs one robot's timers
    of an instant in the order they were armed, at their own instants (it did not:
    the makespans were 59.3 s and 57.4 s).
    """
    assert lossy[2].results["makespan"] == lossy[1].results["makespan"]
    assert lossy[2].trace == lossy[1].trace
