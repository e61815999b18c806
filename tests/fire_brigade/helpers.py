"""Running Fire Brigade scenarios from tests: virtual time, in-memory transport, checked."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import cas_async
from cas_async.scenario import RunResult, Trace, load_scenario, run_scenario
from cas_async.sim import Environment

SCENARIOS = Path(__file__).resolve().parents[2] / "apps" / "fire_brigade" / "scenarios"
VIRTUAL = ("run.virtual=true", 'run.transport="memory"')


def run_checked(
    scenario: Path | str,
    overrides: Sequence[str] = (),
    *,
    virtual: bool = True,
    observe: Callable[[Environment], None] | None = None,
) -> tuple[RunResult, Trace, int]:
    """Runs a scenario with the full item audit after every item event.

    Returns the result, the trace, and how many times the audit ran. ``observe``
    is also called with the Environment before the robots start.
    """
    loaded = load_scenario(scenario, [*(VIRTUAL if virtual else ()), *overrides])
    audits = 0

    def audit_every_event(environment: Environment) -> None:
        ledger = environment.items

        def check(_event: object) -> None:
            nonlocal audits
            ledger.check()
            audits += 1

        ledger.subscribe(check)
        if observe is not None:
            observe(environment)

    result, trace = cas_async.run(
        run_scenario(loaded, observe=audit_every_event), virtual=loaded.run.virtual
    )
    return result, trace, audits
