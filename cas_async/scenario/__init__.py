"""Scenario files and runs: ``python -m cas_async run scenario.toml``, and the pieces behind it.

* :mod:`.config`: TOML tables to frozen dataclasses, with errors naming file and key;
  ``setting()`` declares a key's default, bounds and doc.
* :mod:`.loader`: a scenario file end to end (``app``, ``[run]``, ``[world]``, the app's
  sections, ``--set`` overrides).
* :mod:`.app`: the contract an application implements (:class:`SimulationApp`), and
  the levels of its stack a scenario may replace (:class:`LayerSlot`).
* :mod:`.objective`: what a mission is for (:class:`Objective`): its end, progress,
  checks and results; :class:`Items` retires items of the Environment's ledger.
* :mod:`.runner`: one run as a coroutine, or step by step (:class:`ScenarioRun`:
  ``now()`` and ``progress()`` say where it stands); :mod:`.background`: a run on
  a loop of its own in a worker thread, for an asyncio service (:class:`BackgroundRun`);
  :mod:`.results`: what it measured; :mod:`.drop_policy`: drops that fail a run
  (:class:`FailOnDrops`); :mod:`.listener`: what a run tells a :class:`RunListener`
  as it goes (the live view is one).
* :mod:`.scene`: the static scene an application declares for the views
  (:class:`Scene` of :class:`Disc`, :class:`Rect`, :class:`Polyline`, :class:`Spot`).
* :mod:`.trace`, :mod:`.report`, :mod:`.plots`, :mod:`.progress`: positions over time,
  the summary table and results.json, PNG figures, the live progress line.
* :mod:`.sweep`: a scenario over a grid of values and seeds in worker processes
  (:func:`sweep`; step by step :func:`plan_sweep`, :func:`run_sweep`), summarised
  per point and metric (:class:`SweepOutcome`, :func:`sweep_table`).
"""

from ._app import LayerSlot, Measure, Mission, SimulationApp, SimulationSetup
from ._background import BackgroundRun
from ._config import ScenarioError, from_toml, setting
from ._drop_policy import FailOnDrops
from ._listener import RunListener
from ._loader import (
    DEFAULT_LATENCY,
    FaultsConfig,
    NetworkConfig,
    RunConfig,
    Scenario,
    WorldConfig,
    apply_overrides,
    load_scenario,
    parse_override,
)
from ._objective import Items, Objective, Tally, Watch
from ._plots import write_plots
from ._progress import Progress
from ._report import results_dict, statistics, summary_table, write_results
from ._results import RunProgress, RunResult, RunStatus
from ._run_scenario import run_scenario
from ._run_transport import check_key
from ._runner import ScenarioRun
from ._scene import Disc, Polyline, Rect, Scene, Shape, Spot
from ._sweep import run_sweep, sweep
from ._sweep_grid import SweepAxis, SweepPlan, parse_vary, plan_sweep
from ._sweep_report import sweep_table
from ._sweep_results import MetricStats, SweepOutcome, SweepRun
from ._trace import Trace, TraceCsv

__all__ = [
    "BackgroundRun",
    "DEFAULT_LATENCY",
    "Disc",
    "FailOnDrops",
    "FaultsConfig",
    "Items",
    "LayerSlot",
    "Measure",
    "MetricStats",
    "Mission",
    "NetworkConfig",
    "Objective",
    "Polyline",
    "Progress",
    "Rect",
    "RunConfig",
    "RunListener",
    "RunProgress",
    "RunResult",
    "RunStatus",
    "Scenario",
    "ScenarioError",
    "ScenarioRun",
    "Scene",
    "Shape",
    "SimulationApp",
    "SimulationSetup",
    "Spot",
    "SweepAxis",
    "SweepOutcome",
    "SweepPlan",
    "SweepRun",
    "Tally",
    "Trace",
    "TraceCsv",
    "Watch",
    "WorldConfig",
    "apply_overrides",
    "check_key",
    "from_toml",
    "load_scenario",
    "parse_override",
    "parse_vary",
    "plan_sweep",
    "results_dict",
    "run_scenario",
    "run_sweep",
    "setting",
    "statistics",
    "summary_table",
    "sweep",
    "sweep_table",
    "write_plots",
    "write_results",
]
