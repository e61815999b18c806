"""The counts of a run across processes, summed: every worker's last report, and the world's.

A worker reports its :class:`~._control.Counts` every so often and in its
:class:`~._control.Bye`; the world sums them (a lost worker's are its last
report's) with its own refusals, for ``results.json``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from ._control import Counts

__all__ = ["summed_faults", "summed_messages"]


def summed_faults(reports: Iterable[Counts]) -> dict[str, int] | None:
    """The ``[faults]`` counts of every worker's robots, summed (``None``: no faults)."""
    total: dict[str, int] | None = None
    for counts in reports:
        if counts.faults is not None:
            total = _added(total or {}, counts.faults)
    return total


def summed_messages(
    reports: Iterable[Counts], *own: Mapping[str, int]
) -> tuple[dict[str, dict[str, int]], dict[str, int]]:
    """Every worker's message counts by kind and class, and drop reasons, summed.

    A worker's control-plane refusals are drops too, and so is each of ``own``:
    the world's drops by reason (its refusals, the tokens it counted).
    """
    total: dict[str, dict[str, int]] = {"internal": {}, "external": {}}
    dropped: dict[str, int] = {}
    for counts in reports:
        _added(total["internal"], counts.internal)
        _added(total["external"], counts.external)
        _added(dropped, counts.dropped)
        _added(dropped, counts.refused)
    for drops in own:
        _added(dropped, drops)
    return total, dropped


def _added(total: dict[str, int], counts: Mapping[str, int]) -> dict[str, int]:
    """Adds ``counts`` into ``total``, name by name; returns ``total``."""
    for name, n in counts.items():
        total[name] = total.get(name, 0) + n
    return total
