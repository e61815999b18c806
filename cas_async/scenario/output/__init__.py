"""What a run measured, and how it is written: results, traces, figures.

* :class:`RunResult` (with :class:`RunStatus`, :class:`RunProgress`): what a run
  measured, the data behind everything below;
* :class:`Trace` and :class:`TraceCsv`: where the robots were over simulated time,
  in memory and as ``trace.csv``;
* :func:`results_dict`, :func:`write_results`, :func:`summary_table`,
  :func:`statistics`: ``results.json`` and the plain-text summary;
* :func:`write_plots`: the PNG figures (the thesis's Figs. 33-36);
* :class:`Progress`: the live progress line of a run;
* :func:`atomic_text_file`, :func:`atomic_binary_file`: files written whole or not
  at all, as every output of a run is.
"""

from ._atomic_files import AtomicFile, atomic_binary_file, atomic_text_file
from ._plots import write_plots
from ._progress import Progress
from ._report import results_dict, statistics, summary_table, write_results
from ._results import RunProgress, RunResult, RunStatus
from ._trace import Trace, TraceCsv

__all__ = [
    "AtomicFile",
    "Progress",
    "RunProgress",
    "RunResult",
    "RunStatus",
    "Trace",
    "TraceCsv",
    "atomic_binary_file",
    "atomic_text_file",
    "results_dict",
    "statistics",
    "summary_table",
    "write_plots",
    "write_results",
]
