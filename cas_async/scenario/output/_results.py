"""What a scenario run measured: the data behind the summary table, results.json and plots."""

from __future__ import annotations

import enum
import numbers
import reprlib
from dataclasses import dataclass, field
from statistics import fmean
from typing import Any, Final, Self

import numpy as np

__all__ = ["ExtraValueError", "Extras", "RunProgress", "RunResult", "RunStatus"]

_SHORT: Final = reprlib.Repr()
_SHORT.maxstring = _SHORT.maxother = 40  # a value in an error line, kept short


class RunStatus(enum.StrEnum):
    """How a run ended (the rule, the same however the run is run: ``docs/app-contract.md``).

    A run is *completed* at the instant its objective is met, whatever the robots do
    after; *stopped* when every robot stopped (their layers' termination conditions
    held, or ``robot.stop()``) before it; *timed out* at ``run.max_time``, or at once
    when nothing can happen any more. Failed and interrupted runs end where that
    happened.
    """

    COMPLETED = "completed"
    """The mission's target was reached."""
    STOPPED = "stopped"
    """Every robot stopped before the target was reached."""
    INTERRUPTED = "interrupted"
    """Stopped by the user (Ctrl-C) before the target."""
    TIMED_OUT = "timed_out"
    """``run.max_time`` simulated seconds passed before the target."""
    FAILED = "failed"
    """A layer raised; ``RunResult.error`` says which and why."""


class ExtraValueError(TypeError):
    """A value of ``RunResult.extra`` that is not one figure: refused where it is set."""


def extra_value(key: object, value: object) -> float | int | str:
    """``value`` as ``RunResult.extra[key]`` holds it; refuses what is not one figure.

    A figure is a number, a ``str`` or a ``bool``: the summary shows it on one line,
    results.json holds it as is, a sweep tabulates the numbers. numpy's scalars
    are taken as the Python number (or bool) they hold.

    Raises:
        ExtraValueError: ``key`` is not a ``str``, or ``value`` not a figure (a
            dict, a list, ``None``...), with one line naming both.
    """
    if not isinstance(key, str):
        raise ExtraValueError(
            f"RunResult.extra[{_SHORT.repr(key)}]: the key is not a str ({_kind(key)}); "
            "an extra's key is its name"
        )
    if isinstance(value, bool | str):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        return float(value)
    raise ExtraValueError(
        f"RunResult.extra[{key!r}] = {_SHORT.repr(value)}: not one figure ({_kind(value)}); "
        "an extra value is a number (int, float), a str or a bool (values per thing done "
        "go in RunResult.samples)"
    )


def _kind(value: object) -> str:
    kind = type(value)
    return kind.__name__ if kind.__module__ == "builtins" else f"{kind.__module__}.{kind.__name__}"


class Extras(dict[str, float | int | str]):
    """``RunResult.extra``: a dict that refuses, where it is set, what is not one figure.

    Every way of setting an entry (``extras[key] = value``, ``update``,
    ``setdefault``, ``|=``, the constructor) goes through :func:`extra_value`.
    """

    __slots__ = ()

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__()
        self.update(*args, **kwargs)

    def __setitem__(self, key: str, value: float | int | str) -> None:
        super().__setitem__(key, extra_value(key, value))

    def update(self, *args: Any, **kwargs: Any) -> None:
        for key, value in dict(*args, **kwargs).items():
            self[key] = value

    def setdefault(self, key: str, default: float | int | str) -> float | int | str:
        if key not in self:
            self[key] = default
        return self[key]

    def __ior__(self, other: Any) -> Self:  # type: ignore[override,misc]
        self.update(other)
        return self


@dataclass(slots=True)
class RunResult:
    """Everything one run measured. Times are simulated seconds unless named ``wall``.

    Attributes:
        scenario: the scenario file's path, as given.
        app: the application's name (e.g. ``"Fire Brigade"``).
        item_name: what the mission's target counts, singular (``"bucket"``,
            ``"object"``: the objective's ``noun``).
        seed: the seed of the run.
        status: how it ended.
        error: the failure's message when ``status`` is FAILED.
        traceback: the failure's traceback (of the layer's own exception).
        target: how many must be done for the mission to be complete.
        created: items created during the run (an item mission only).
        delivered: how many were done: items delivered (retired), objects moved.
        exchanges: hand-overs of an item from one robot to another (an item mission only).
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
        extra: application-specific figures, shown in the table and written to JSON:
            one per name, each a number, a ``str`` or a ``bool``; anything else
            (a dict, a list, ``None``) is refused where it is set, with a
            ``TypeError`` that names the key.
        metrics: application-defined measures of the swarm's positions, each
            summarised as one number (see :class:`~cas_async.scenario.Mission`'s
            ``measures``): the mean over the last third of the run's samples.
        series: each of those measures over time: ``{"t": [...], "value": [...]}``;
            and by exchange count in ``by_exchange``: ``{"count": [...], "value": [...]}``.
        delivery_times: the simulated instant each was done (delivered), in order.
        kind: the objective's kind: ``"items"`` (the item fields above are
            measured) or the application's own.
        verb: what was done to each (``"delivered"``, ``"moved"``).
        detail: the name of the progress line's second count (``"exchanges"``).
        samples: an objective's own values per thing done (``"time_per_object"``):
            summarised with :func:`~cas_async.scenario.output.statistics` in the table and
            results.json.
        fail_on_drops: the drop reasons that fail the run (``run --fail-on-drops``;
            empty: any reason), ``None`` when drops fail nothing (the default).
        failing_drops: the drops, by reason, that failed the run (or would have:
            a run that failed for something else keeps its error).
        unanswered: internal requests still unanswered when the run ended, whose
            asked layer's ``get_intra_msg_reply`` had returned ``None``: how many,
            by ``"robot layer asked Request of layer"`` (see
            :meth:`~cas_async.Robot.unanswered_requests`).
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
    extra: dict[str, float | int | str] = field(default_factory=Extras)
    metrics: dict[str, float] = field(default_factory=dict)
    series: dict[str, dict[str, list[float]]] = field(default_factory=dict)
    by_exchange: dict[str, dict[str, list[float]]] = field(default_factory=dict)
    delivery_times: list[float] = field(default_factory=list)
    kind: str = "items"
    verb: str = "delivered"
    detail: str = "exchanges"
    samples: dict[str, list[float]] = field(default_factory=dict)
    fail_on_drops: list[str] | None = None
    failing_drops: dict[str, int] = field(default_factory=dict)
    unanswered: dict[str, int] = field(default_factory=dict)

    def scalars(self) -> dict[str, float]:
        """The run's figures as numbers, one per name: what a sweep tabulates.

        ``makespan`` (absent when the target was not reached), ``sim_time``,
        ``delivered``, ``exchanges`` (an item mission's), ``exchanges_per_item``
        (mean hand-overs per delivered item), ``travel_time`` (mean), ``distance`` (mean per mobile
        robot), ``wall_time``, the mean of each of ``samples``, then every entry of
        ``metrics`` and every numeric entry of ``extra``.
        """
        figures: dict[str, float] = {}
        if self.makespan is not None:
            figures["makespan"] = self.makespan
        figures["sim_time"] = self.sim_time
        figures["delivered"] = float(self.delivered)
        if self.kind == "items":
            figures["exchanges"] = float(self.exchanges)
        if self.handovers_per_item:
            figures["exchanges_per_item"] = fmean(self.handovers_per_item)
        if self.travel_times:
            figures["travel_time"] = fmean(self.travel_times)
        if self.distance:
            figures["distance"] = fmean(self.distance.values())
        figures["wall_time"] = self.wall_time
        for name, values in self.samples.items():
            if values:
                figures[name] = fmean(values)
        figures.update(self.metrics)
        for name, value in self.extra.items():
            if isinstance(value, int | float) and not isinstance(value, bool):
                figures.setdefault(name, float(value))
        return figures

    def __setattr__(self, name: str, value: object) -> None:
        if name == "extra" and not isinstance(value, Extras):  # a dict given whole: checked
            value = Extras(value)
        object.__setattr__(self, name, value)


@dataclass(frozen=True, slots=True)
class RunProgress:
    """Where a run stands: what its progress line shows, as numbers.

    Attributes:
        time: simulated seconds since the robots started (0 before).
        done: how many of the target are done (buckets delivered, objects moved).
        target: how many must be done for the mission to be complete (0 until the
            robots are built).
        detail: the progress line's second count (exchanges, for an item mission).
        status: how the run ended; ``None`` while it has not.
    """

    time: float = 0.0
    done: int = 0
    target: int = 0
    detail: int = 0
    status: RunStatus | None = None

    @property
    def fraction(self) -> float:
        """``done / target``, between 0 and 1 (0 while the target is not known)."""
        return min(1.0, self.done / self.target) if self.target > 0 else 0.0

    @property
    def ended(self) -> bool:
        """Whether the run has ended (its :attr:`status` is known)."""
        return self.status is not None
