"""Scenario files and runs: the application contract, the file, running one.

The application contract:

* :class:`SimulationApp` builds a :class:`Mission` from a :class:`SimulationSetup`
  (with its :class:`Measure`); :class:`LayerSlot` names the levels of its stack a
  scenario may replace; :class:`Objective` (:class:`Items`, :class:`Tally`,
  :class:`Watch`) says what the mission is for; :class:`Scene` (of :class:`Disc`,
  :class:`Rect`, :class:`Polyline`, :class:`Spot`) what the views draw;
* :func:`setting` declares a key of an app's own section, :func:`from_toml` reads
  one, :class:`ScenarioError` says what is wrong and where.

The scenario file: :func:`load_scenario` (or :func:`scenario_from_data` for a table
already read) gives a :class:`Scenario` of :class:`RunConfig`, :class:`WorldConfig`,
:class:`NetworkConfig` and :class:`FaultsConfig`; :func:`parse_override` and
:func:`apply_overrides` are ``--set``; :func:`check_key` checks a swarm key against it.

Running one: :func:`run_scenario` (all at once), :class:`ScenarioRun` (step by
step), :class:`BackgroundRun` (beside an asyncio service); each gives a
:class:`RunResult` (:class:`RunStatus`, :class:`RunProgress`); a
:class:`RunListener` follows a run; :class:`FailOnDrops` fails one on drops.

Beside this face: :mod:`cas_async.scenario.output` (results, traces, reports,
figures) and :mod:`cas_async.scenario.sweeps` (a scenario over a grid of values).
"""

from .._deprecation import Heir as _Heir
from .._deprecation import moved_names as _moved_names
from ._run._background import BackgroundRun
from ._run._drop_policy import FailOnDrops
from ._run._listener import RunListener
from ._run._run_scenario import run_scenario
from ._run._runner import ScenarioRun
from ._spec._app import LayerSlot, Measure, Mission, SimulationApp, SimulationSetup
from ._spec._config import ScenarioError, from_toml, setting
from ._spec._loader import (
    DEFAULT_LATENCY,
    FaultsConfig,
    NetworkConfig,
    RunConfig,
    Scenario,
    WorldConfig,
    apply_overrides,
    load_scenario,
    parse_override,
    scenario_from_data,
)
from ._spec._objective import Items, Objective, Tally, Watch
from ._spec._run_transport import check_key
from ._spec._scene import Disc, Polyline, Rect, Scene, Shape, Spot
from .output import RunProgress, RunResult, RunStatus

__all__ = [
    "BackgroundRun",
    "DEFAULT_LATENCY",
    "Disc",
    "FailOnDrops",
    "FaultsConfig",
    "Items",
    "LayerSlot",
    "Measure",
    "Mission",
    "NetworkConfig",
    "Objective",
    "Polyline",
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
    "Tally",
    "Watch",
    "WorldConfig",
    "apply_overrides",
    "check_key",
    "from_toml",
    "load_scenario",
    "parse_override",
    "run_scenario",
    "scenario_from_data",
    "setting",
]

_OUTPUT = "cas_async.scenario.output"
_SWEEP = "cas_async.scenario.sweeps"

_deprecated = _moved_names(
    __name__,
    {
        **{
            name: _Heir(_OUTPUT)
            for name in (
                "Progress", "Trace", "TraceCsv", "results_dict", "statistics",
                "summary_table", "write_plots", "write_results",
            )
        },
        **{
            name: _Heir(_SWEEP)
            for name in (
                "MetricStats", "SweepAxis", "SweepOutcome", "SweepPlan", "SweepRun",
                "parse_vary", "plan_sweep", "run_sweep", "sweep", "sweep_table",
            )
        },
    },
)  # fmt: skip
"""Names this face gave in 0.1.0 that moved to its stages' faces (``CHANGELOG.md``)."""


def __getattr__(name: str) -> object:
    return _deprecated(name)  # a name that moved gives its heir, with a warning
