"""Running Fire Brigade scenarios from tests: virtual time, in-memory transport, checked."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path

from cas_async.scenario import RunResult
from cas_async.scenario.output import Trace
from cas_async.sim import Environment, ItemEvent, ItemEventKind
from cas_async.testing import run_scenario_file

SCENARIOS = Path(__file__).resolve().parents[2] / "apps" / "fire_brigade" / "scenarios"
VIRTUAL = ("run.virtual=true", 'run.transport="memory"')


def run_checked(
    scenario: Path | str,
    overrides: Sequence[str] = (),
    *,
    virtual: bool = True,
    observe: Callable[[Environment], None] | None = None,
) -> tuple[RunResult, Trace, Counter[ItemEventKind]]:
    """Runs a scenario with the full item audit after every item event.

    Returns the result, the trace, and how many times the audit ran, by the kind
    of the event it followed. ``observe`` is also called with the Environment
    before the robots start.
    """
    audits: Counter[ItemEventKind] = Counter()

    def audit_every_event(environment: Environment) -> None:
        ledger = environment.items

        def check(event: ItemEvent) -> None:
            ledger.check()
            audits[event.kind] += 1

        ledger.subscribe(check)
        if observe is not None:
            observe(environment)

    outcome = run_scenario_file(scenario, *overrides, virtual=virtual, observe=audit_every_event)
    return outcome.result, outcome.trace, audits
