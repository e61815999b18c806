"""Virtual time shared by processes: a barrier that grants the next instant to all at once.

Each process of a simulation (the world and every worker) runs a
:class:`BarrierLoop`. Where a lone :class:`~cas_async._virtual_loop.VirtualTimeLoop`
jumps to its next timer as soon as it is idle, a barrier loop reports instead, and
waits: its next deadline and how many cross-process messages it has sent and
received. The world's :class:`Coordinator` grants the earliest deadline of all once
every process is idle and nothing is in flight (the conservative "next event
request / grant" of HLA time management); every loop then jumps to that instant.
A message sent at virtual instant ``t`` is therefore received at ``t`` too: time
cannot move while it travels.

"Nothing in flight" is decided by counting (Mattern's four counters): the sums of
messages sent and received over all processes' latest reports must agree, and a
second round (``prepare``/``confirm``) checks that no process has sent or received
anything since it reported. One round alone can be fooled by stale reports: a
process that reported idle, then received a message and sent another, leaves sums
that agree while it is busy. With the second round, the state counted was stable,
so the grant is safe.

If every deadline is infinite, no process will ever act again: the run is over
(distributed termination), and the grant says so (``inf``).

What counts as a message is the caller's (robot datagrams between processes,
published motions, item requests and replies); control traffic of the barrier
itself is not counted.
"""

from __future__ import annotations

import math
import selectors
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

from .._virtual_loop import VirtualTimeLoop

__all__ = ["BarrierLoop", "Coordinator", "Participant", "Report"]

WORLD: Final = -1
"""The world's participant id (workers are 0..n-1)."""


@dataclass(frozen=True, slots=True)
class Report:
    """An idle process's report: in which round, its next deadline, its message counts."""

    round: int
    deadline: float
    sent: int
    received: int


class Participant:
    """One process's side of the barrier: reports when idle, holds the grant it got.

    Args:
        ident: the process's participant id (:data:`WORLD` or a worker index).
        counts: returns ``(sent, received)`` of counted messages so far.
        report: sends a :class:`Report` to the coordinator (a message, or a call
            for the world's own participant).
    """

    def __init__(
        self,
        ident: int,
        counts: Callable[[], tuple[int, int]],
        report: Callable[[int, Report], None],
    ) -> None:
        self.ident = ident
        self._counts = counts
        self._report = report
        self.round = 0
        self.rounds = 0  # grants received: the barrier's rounds in this process
        self._last: Report | None = None
        self._grant: float | None = None
        self.over = False
        """Every deadline was infinite: the run is over."""

    def idle(self, deadline: float) -> None:
        """The loop is idle until ``deadline``: reports, unless it said exactly that already."""
        sent, received = self._counts()
        report = Report(self.round, deadline, sent, received)
        if report != self._last:
            self._last = report
            self._report(self.ident, report)

    def unchanged(self) -> bool:
        """Whether nothing was sent or received since the last report (a ``confirm``)."""
        last = self._last
        return last is not None and (last.sent, last.received) == self._counts()

    def granted(self, round_: int, until: float) -> None:
        """The coordinator granted time ``until`` as round ``round_`` begins."""
        if round_ <= self.round:
            return  # a grant seen before
        self.round = round_
        self.rounds += 1
        self._grant = until
        self._last = None  # report again once idle at the new instant

    def has_grant(self) -> bool:
        """Whether a grant waits to be used."""
        return self._grant is not None

    def take_grant(self) -> float | None:
        """The instant granted and not yet used, once."""
        grant, self._grant = self._grant, None
        return grant


class BarrierLoop(VirtualTimeLoop):
    """A virtual-time loop whose idle jumps wait for the barrier (see the module docs).

    Until :meth:`activate`, time stands still at 0 and the idle loop just waits
    for other threads (Zenoh's): the processes set up and connect first.
    """

    def __init__(self) -> None:
        super().__init__()
        self.participant: Participant | None = None

    def activate(self, participant: Participant) -> None:
        """Time moves from now on, as the barrier grants it."""
        self.participant = participant

    def when_idle(
        self, timeout: float | None, selector: selectors.BaseSelector
    ) -> list[tuple[selectors.SelectorKey, int]]:
        participant = self.participant
        if participant is None or participant.over:
            return selector.select(None if timeout is None else 0.05)  # setting up: no time
        grant = participant.take_grant()
        if grant is not None:
            if grant == math.inf:
                participant.over = True
                return []
            now = self.time()
            if grant > now:
                self.advance(grant - now)
            return []
        participant.idle(math.inf if timeout is None else self.time() + timeout)
        if participant.has_grant():  # the world's own report completed a round
            return []
        return selector.select(None)


class Coordinator:
    """The world's side: collects reports, checks them twice, grants the next instant.

    Args:
        workers: how many worker participants (ids ``0..workers-1``), besides the world.
        prepare: asks every worker to confirm that nothing changed since it reported
            (``prepare(ticket)``, a number new for every prepare); answers come back
            through :meth:`confirmed`, naming the ticket they answer.
        grant: tells every worker the new round and the instant granted.
        world: the world's own participant, asked directly.
    """

    def __init__(
        self,
        workers: int,
        prepare: Callable[[int], None],
        grant: Callable[[int, float], None],
    ) -> None:
        self._ids = frozenset(range(workers)) | {WORLD}
        self._prepare = prepare
        self._grant = grant
        self._reports: dict[int, Report] = {}
        self._confirms: set[int] = set()
        self._preparing = False
        self._ticket = 0  # one per prepare: an answer to an abandoned one counts for nothing
        self.round = 0
        self.world: Participant | None = None
        self.rounds = 0
        self.aborted = 0  # prepare rounds that found a change: what one-round counting would miss

    def report(self, ident: int, report: Report) -> None:
        """A participant is idle (its latest report replaces the earlier ones)."""
        if report.round != self.round or ident not in self._ids:
            return  # from a round already over, or from no participant
        self._reports[ident] = report
        if self._preparing:  # something changed while confirming: start over
            self._preparing = False
            self._confirms.clear()
            self.aborted += 1
        self._check()

    def confirmed(self, ident: int, ticket: int, unchanged: bool) -> None:
        """A participant's answer to the ``prepare`` of ``ticket``."""
        if not self._preparing or ticket != self._ticket:
            return
        if not unchanged:
            self._preparing = False
            self._confirms.clear()
            self.aborted += 1
            return
        self._confirms.add(ident)
        self._check()

    def _check(self) -> None:
        reports = self._reports
        if len(reports) < len(self._ids):
            return
        if not self._preparing:
            if sum(r.sent for r in reports.values()) != sum(r.received for r in reports.values()):
                return  # something is still in flight: its receiver will report again
            self._preparing = True
            self._confirms.clear()
            world = self.world
            if world is not None and world.unchanged():
                self._confirms.add(WORLD)
            elif world is not None:
                self._preparing = False
                self.aborted += 1
                return
            self._ticket += 1
            self._prepare(self._ticket)
            return
        if self._confirms != self._ids:
            return
        until = min(r.deadline for r in reports.values())
        self._preparing = False
        self._confirms.clear()
        self._reports.clear()
        self.round += 1
        self.rounds += 1
        self._grant(self.round, until)
        if self.world is not None:
            self.world.granted(self.round, until)
