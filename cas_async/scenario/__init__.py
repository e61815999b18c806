"""Scenario files and runs: ``python -m cas_async run scenario.toml``, and the pieces behind it.

* :mod:`.config`: TOML tables to frozen dataclasses, with errors naming file and key;
  ``setting()`` declares a key's default, bounds and doc.
* :mod:`.loader`: a scenario file end to end (``app``, ``[run]``, ``[world]``, the app's
  sections, ``--set`` overrides).
* :mod:`.app`: the contract an application implements (:class:`SimulationApp`).
* :mod:`.runner`: one run as a coroutine, or step by step (:class:`ScenarioRun`);
  :mod:`.results`: what it measured.
* :mod:`.trace`, :mod:`.report`, :mod:`.plots`, :mod:`.progress`: positions over time,
  the summary table and results.json, PNG figures, the live progress line.
"""

from ._app import Mission, SimulationApp, SimulationSetup
from ._config import ScenarioError, from_toml, setting
from ._loader import (
    FaultsConfig,
    RunConfig,
    Scenario,
    WorldConfig,
    apply_overrides,
    load_scenario,
    parse_override,
)
from ._plots import write_plots
from ._progress import Progress
from ._report import results_dict, statistics, summary_table, write_results
from ._results import RunResult, RunStatus
from ._runner import ScenarioRun, check_key, run_scenario
from ._trace import Trace, TraceCsv

__all__ = [
    "FaultsConfig",
    "Mission",
    "Progress",
    "RunConfig",
    "RunResult",
    "RunStatus",
    "Scenario",
    "ScenarioError",
    "ScenarioRun",
    "SimulationApp",
    "SimulationSetup",
    "Trace",
    "TraceCsv",
    "WorldConfig",
    "apply_overrides",
    "check_key",
    "from_toml",
    "load_scenario",
    "parse_override",
    "results_dict",
    "run_scenario",
    "setting",
    "statistics",
    "summary_table",
    "write_plots",
    "write_results",
]
