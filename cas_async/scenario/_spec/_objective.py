"""What a mission is for: its end, its progress, its checks and its results.

The scenario runner knows no kind of work. It asks the mission's
:class:`Objective`, which the application chooses:

* :meth:`Objective.attach` once the robots are built and before they start:
  the objective subscribes to what it follows (the Environment's items, a world
  of the application's own) and from then on tells the runner, through the
  :class:`Watch` it was given, when its progress changed and when the mission is
  complete;
* :meth:`Objective.progress` whenever the progress line is drawn: how many of
  the target are done, and one more count to show beside them;
* :meth:`Objective.check` at every sample of the run: a full audit of the
  objective's invariant (raise to fail the run);
* :meth:`Objective.carrying` at every sample: the robots to mark as carrying
  something in the trace and the figures;
* :meth:`Objective.measure` once, as the run ends: it writes its figures into
  the :class:`~cas_async.scenario.RunResult`;
* :meth:`Objective.figures` when the figures are drawn: files of its own.

:class:`Items` is the ready-made objective of a mission that retires items
through the Environment's item ledger (the Fire Brigade's buckets). An
application whose work is something else (moving boxes, covering an area)
writes its own: a few dozen lines.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections import Counter
from collections.abc import Callable, Collection
from pathlib import Path
from typing import NamedTuple, Protocol, final

from ..._time._clock import Clock
from ..._types import RobotId
from ...sim._environment import Environment
from ...sim._item_events import ItemEvent, ItemEventKind
from ..output._results import RunResult
from ..output._trace import Trace

__all__ = [
    "CallbackWatch",
    "Items",
    "Objective",
    "Tally",
    "Watch",
    "not_distributable",
]


class Tally(NamedTuple):
    """How far a mission is: what the progress line shows.

    Attributes:
        done: how many of the target are done (buckets delivered, objects moved).
        detail: the second count the line shows, named by :attr:`Objective.detail`.
    """

    done: int
    detail: int = 0


class Watch(Protocol):
    """What the runner gives an objective to report to (see :meth:`Objective.attach`).

    Calls after the run ended are ignored: what happens then is not the run's.
    """

    @property
    def environment(self) -> Environment:
        """The run's Environment: the robots' poses, distances and items."""

    @property
    def clock(self) -> Clock:
        """The run's clock: ``clock.now()`` is the simulated instant."""

    def now(self) -> float:
        """The instant the run observes its robots at: the sample's, while it samples.

        Where :meth:`Objective.check` should look. It is ``clock.now()`` in a run whose
        robots run here; a world process observes its workers' robots window by
        window while its own clock stands still, so there only this is right.
        """

    def changed(self, t: float) -> None:
        """Progress changed at simulated instant ``t``: the line may be redrawn."""

    def completed(self, t: float) -> None:
        """The mission is complete, at simulated instant ``t`` (its makespan): the run ends."""

    def exchanged(self, t: float, count: int) -> None:
        """The ``count``-th exchange happened at ``t``: snapshot every robot's position.

        The snapshots are what the figures and measures "by exchange" use; only
        when ``run.trace_exchanges`` is on.
        """


@final
class CallbackWatch:
    """A :class:`Watch` that calls back: what a run gives its objective (internal)."""

    __slots__ = ("_clock", "_environment", "_sampled", "changed", "completed", "exchanged")

    def __init__(
        self,
        environment: Environment,
        clock: Clock,
        *,
        changed: Callable[[float], None],
        completed: Callable[[float], None],
        exchanged: Callable[[float, int], None],
    ) -> None:
        self._environment = environment
        self._clock = clock
        self._sampled: float | None = None  # the instant of the sample being taken
        self.changed = changed
        self.completed = completed
        self.exchanged = exchanged

    @property
    def environment(self) -> Environment:
        """The run's Environment."""
        return self._environment

    @property
    def clock(self) -> Clock:
        """The run's clock."""
        return self._clock

    def now(self) -> float:
        """The instant of the sample being taken, else the clock's."""
        return self._clock.now() if self._sampled is None else self._sampled

    def sampling(self, t: float | None) -> None:
        """The runner takes a sample at ``t`` (``None``: done with it)."""
        self._sampled = t


class Objective(ABC):
    """What a mission is for; see the module docs for when the runner calls what.

    Attributes:
        noun: what the target counts, singular (``"bucket"``, ``"object"``).
        verb: what happens to one for it to count (``"delivered"``, ``"moved"``).
        detail: the name of the progress line's second count (``"exchanges"``).
        kind: the objective's kind in results.json; ``"items"`` is :class:`Items`'s,
            whose results keep the item fields (created, exchanges, travel times).
        distributable: whether the objective can run across processes
            (``--processes``). There the robots run in worker processes, and the
            world process holds the Environment: every robot's motions and the
            item ledger, as the workers report them. An objective may say ``True``
            when it reads only those (positions, distances, items: the
            Environment and the :class:`Watch`), never a robot's layers or objects
            the layers change (they live in other processes). :class:`Items` does.
    """

    noun: str = "item"
    verb: str = "done"
    detail: str = "events"
    kind: str = "custom"
    distributable: bool = False

    @property
    @abstractmethod
    def target(self) -> int:
        """How many must be done for the mission to be complete."""

    @abstractmethod
    def attach(self, watch: Watch) -> None:
        """Starts following the mission; report to ``watch`` from now on."""

    @abstractmethod
    def progress(self) -> Tally:
        """How far the mission is now."""

    def check(self) -> None:  # noqa: B027 - optional hook, empty by design
        """Audits the objective's invariant; raise to fail the run (default: nothing)."""

    def carrying(self) -> Collection[RobotId]:
        """The robots carrying something now (default: none)."""
        return ()

    @abstractmethod
    def measure(self, result: RunResult, end: float) -> None:
        """Writes what the objective measured into ``result``, once, as the run ended at ``end``.

        ``end`` may be later than the completion: on scaled time the robots go on
        a moment before the run ends, so an objective counts only what happened
        up to the instant it called ``completed`` (``result.makespan``).

        Set ``result.delivered`` (how many were done), ``result.delivery_times``
        (the instant each was done) and, for an objective of one's own, any
        ``result.samples`` (named values per thing done, summarised with
        statistics) and ``result.extra`` figures. The runner has already set
        the status, the makespan and the robots' distances.
        """

    def figures(self, trace: Trace, out_dir: Path) -> list[Path]:
        """Draws the objective's own figures into ``out_dir``; returns their paths (default: none).

        Called after the runner's figures, only when figures are wanted (and
        matplotlib is installed).
        """
        del trace, out_dir
        return []


class Items(Objective):
    """Retire ``target`` items of the Environment's item ledger (the Fire Brigade's buckets).

    Progress is the items retired, beside the hand-overs so far; the mission is
    complete at the retirement of the ``target``-th item, and only the item
    events up to it are measured. Every sample audits the ledger (no item lost
    or duplicated); the robots holding an item are the ones carrying.

    Args:
        target: items to retire.
        noun: what an item is, singular (``"bucket"``).
    """

    verb = "delivered"
    detail = "exchanges"
    kind = "items"
    distributable = True

    def __init__(self, target: int, noun: str = "item") -> None:
        if target < 0:
            raise ValueError(f"Items: target must not be negative, got {target}")
        self._target = target
        self.noun = noun
        self._watch: Watch | None = None
        self._environment: Environment | None = None
        self._measured: int | None = None  # item events up to the target, once reached

    @property
    def target(self) -> int:
        """Items to retire."""
        return self._target

    def attach(self, watch: Watch) -> None:
        """Follows the Environment's item ledger."""
        self._watch = watch
        self._environment = watch.environment
        watch.environment.items.subscribe(self._on_item)

    def _ledger_environment(self) -> Environment:
        if self._environment is None:
            raise RuntimeError("Items: not attached to a run yet")
        return self._environment

    def _on_item(self, event: ItemEvent) -> None:
        watch, ledger = self._watch, self._ledger_environment().items
        if watch is None or self._measured is not None:  # what comes after is not the run's
            return
        if event.kind is ItemEventKind.TRANSFERRED:
            watch.exchanged(event.t, ledger.transfers)
        elif event.kind is ItemEventKind.RETIRED and ledger.retired == self._target:
            # The run ends here: an item retired before the loop gets round to ending
            # it (on scaled time, a moment later) is not the run's.
            self._measured = len(ledger.events)
            watch.completed(event.t)
        watch.changed(event.t)

    def progress(self) -> Tally:
        """Items retired, and hand-overs."""
        ledger = self._ledger_environment().items
        return Tally(ledger.retired, ledger.transfers)

    def check(self) -> None:
        """Every item created is retired or held by exactly one robot."""
        self._ledger_environment().items.check()

    def carrying(self) -> Collection[RobotId]:
        """The robots holding an item."""
        return self._ledger_environment().items.holders()

    def measure(self, result: RunResult, end: float) -> None:
        """Items created, retired and handed over; per retired item its travel and hand-overs."""
        del end
        ledger = self._ledger_environment().items
        events = ledger.events
        counted = events if self._measured is None else events[: self._measured]
        kinds = Counter(event.kind for event in counted)
        result.created = kinds[ItemEventKind.CREATED]
        result.delivered = kinds[ItemEventKind.RETIRED]
        result.exchanges = kinds[ItemEventKind.TRANSFERRED]
        for event in counted:
            if event.kind is ItemEventKind.RETIRED:
                result.delivery_times.append(event.t)
                history = ledger.history(event.item)
                result.travel_times.append(event.t - history[0].t)
                result.handovers_per_item.append(
                    sum(e.kind is ItemEventKind.TRANSFERRED for e in history)
                )


def not_distributable(scenario: Path, app: str, objective: Objective) -> str:
    """Why ``objective`` (of ``app``, in file ``scenario``) cannot run across processes: one line.

    It says when an objective could, and how to say so.
    """
    name = type(objective).__name__
    return (
        f"{scenario}: --processes: {app}'s objective {name} is not "
        "distributable. Across processes the robots run in workers and the world process "
        "observes a mirror of their Environment (every robot's motions and the item "
        "ledger); an objective "
        "that reads only those (positions, distances, items: the Environment and its Watch), "
        f"never the robots' layers, may run there: then set distributable = True on {name}. "
        "Otherwise run without --processes."
    )
