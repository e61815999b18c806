"""Experiment sweeps: a scenario over a grid of values and seeds.

``python -m cas_async sweep SCENARIO --seeds N --vary KEY=A,B ...`` in Python:
:func:`sweep` plans and runs one, :func:`plan_sweep` (with :func:`parse_vary`)
and :func:`run_sweep` do it step by step. A :class:`SweepPlan` holds the
:class:`SweepAxis` grid and every run's overrides; a :class:`SweepOutcome` the
finished :class:`SweepRun` records and :class:`MetricStats` per point and metric;
:func:`sweep_table` prints them.

The runs go to worker processes of the sweep's own, to a Dask cluster (given a
``distributed.Client``) or to any ``concurrent.futures.Executor``. Given an
output folder, a sweep writes ``sweep.json`` first and a row of ``runs.csv`` as
each run finishes, and a later one with ``resume=True`` runs only the others.
"""

from ._execution import run_sweep, sweep
from ._files import sweep_table
from ._outcome import MetricStats, SweepOutcome, SweepRun
from ._plan import SweepAxis, SweepPlan, parse_vary, plan_sweep

__all__ = [
    "MetricStats",
    "SweepAxis",
    "SweepOutcome",
    "SweepPlan",
    "SweepRun",
    "parse_vary",
    "plan_sweep",
    "run_sweep",
    "sweep",
    "sweep_table",
]
