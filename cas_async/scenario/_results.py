"""What a scenario run measured: the data behind the summary table, results.json and plots."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

__all__ = ["RunResult", "RunStatus"]


class RunStatus(enum.StrEnum):
    """How a run ended."""

    COMPLETED = "completed"
    """The mission's target was reached."""
    INTERRUPTED = "interrupted"
    """Stopped by the user (Ctrl-C) before the target."""
    TIMED_OUT = "timed_out"
    """``run.max_time`` simulated seconds passed before the target."""
    FAILED = "failed"
    """A layer raised; ``RunResult.error`` says which and why."""


@dataclass(slots=True)
class RunResult:
    """Everything one run measured. Times are simulated seconds unless named ``wall``.

    Attributes:
        scenario: the scenario file's path, as given.
        app: the application's name (e.g. ``"Fire Brigade"``).
        item_name: what the app's items are called (e.g. ``"bucket"``).
        seed: the seed of the run.
        status: how it ended.
        error: the failure's message when ``status`` is FAILED.
        traceback: the failure's traceback (of the layer's own exception).
        target: items to deliver for the mission to be complete.
        created: items created during the run.
        delivered: items delivered (retired).
        exchanges: hand-overs of an item from one robot to another.
        makespan: simulated instant the target was reached (``None`` if it was not).
        sim_time: simulated instant the run ended.
        wall_time: wall-clock seconds from start to end.
        travel_times: per delivered item, delivery instant minus creation instant.
        handovers_per_item: per delivered item, how many times it changed hands
            (the final hand-over to its destination included).
        distance: per mobile robot id, the distance it travelled.
        messages_internal: internal messages sent, by message class name.
        messages_external: external messages sent, by message class name.
        protocol_errors: messages dropped by the runtime, by reason.
        faults: what the ``[faults]`` table did to the datagrams (the counts of
            :attr:`~cas_async.transport._faulty.FaultyTransport.stats`), ``None``
            when the run had no faults.
        groups: robot ids by group label (e.g. ``{"Sink": [3, 4]}``), for tables and plots.
        config: the scenario as loaded (after ``--set`` overrides), as plain TOML data.
        extra: application-specific figures, shown in the table and written to JSON.
    """

    scenario: str
    app: str
    item_name: str
    seed: int
    status: RunStatus = RunStatus.COMPLETED
    error: str | None = None
    traceback: str | None = None
    target: int = 0
    created: int = 0
    delivered: int = 0
    exchanges: int = 0
    makespan: float | None = None
    sim_time: float = 0.0
    wall_time: float = 0.0
    travel_times: list[float] = field(default_factory=list)
    handovers_per_item: list[int] = field(default_factory=list)
    distance: dict[int, float] = field(default_factory=dict)
    messages_internal: dict[str, int] = field(default_factory=dict)
    messages_external: dict[str, int] = field(default_factory=dict)
    protocol_errors: dict[str, int] = field(default_factory=dict)
    faults: dict[str, int] | None = None
    groups: dict[str, list[int]] = field(default_factory=dict)
    config: dict[str, Any] = field(default_factory=dict)
    extra: dict[str, float | int | str] = field(default_factory=dict)
