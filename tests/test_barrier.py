"""The barrier that shares virtual time between processes, without processes.

A :class:`Harness` plays the processes of a run: the world's participant and one
per worker, each with its own counts of messages sent and received, all talking to
one :class:`Coordinator` by plain calls. A message "in flight" is one counted as
sent and not yet as received; a stale report is one made before the participant's
latest send or receipt.
"""

from __future__ import annotations

import asyncio
import math
import threading

from cas_async.scenario._barrier import WORLD, BarrierLoop, Coordinator, Participant, Report

A, B, C = 0, 1, 2


class Harness:
    """A coordinator, the world's participant and ``workers`` worker participants."""

    def __init__(self, workers: int) -> None:
        self.prepares: list[int] = []
        self.grants: list[tuple[int, float]] = []
        self.coordinator = Coordinator(
            workers, self.prepares.append, lambda round_, until: self.grants.append((round_, until))
        )
        self.counts = {ident: [0, 0] for ident in (WORLD, *range(workers))}
        self.sent_reports: list[tuple[int, Report]] = []
        self.parts = {
            ident: Participant(ident, self._counter(ident), self._report) for ident in self.counts
        }
        self.coordinator.world = self.parts[WORLD]

    def _counter(self, ident: int):  # type: ignore[no-untyped-def]
        return lambda: (self.counts[ident][0], self.counts[ident][1])

    def _report(self, ident: int, report: Report) -> None:
        self.sent_reports.append((ident, report))
        self.coordinator.report(ident, report)

    def send(self, sender: int) -> None:
        """``sender`` sends a counted message (it is in flight until someone receives it)."""
        self.counts[sender][0] += 1

    def receive(self, receiver: int) -> None:
        """``receiver`` receives a counted message: it is busy until it reports again."""
        self.counts[receiver][1] += 1

    def idle(self, ident: int, deadline: float) -> None:
        self.parts[ident].idle(deadline)

    def confirm(self, ident: int) -> None:
        """Worker ``ident`` answers the latest ``prepare`` truthfully, at once."""
        self.coordinator.confirmed(ident, self.prepares[-1], self.parts[ident].unchanged())

    def deliver_grant(self) -> None:
        """The latest grant reaches every worker (the world's participant got it directly)."""
        round_, until = self.grants[-1]
        for ident, part in self.parts.items():
            if ident != WORLD:
                part.granted(round_, until)


def test_the_earliest_deadline_is_granted_once_all_are_idle_and_the_counts_balance() -> None:
    h = Harness(2)
    h.idle(WORLD, 5.0)
    h.idle(A, 3.0)
    assert len(h.prepares) == 0  # B has not reported
    h.send(A)  # A sends to B, and reports again
    h.idle(A, 3.0)
    h.idle(B, 4.0)  # B reported before the message arrived
    assert len(h.prepares) == 0  # every report in, but one message in flight
    h.receive(B)
    h.idle(B, 4.0)
    assert len(h.prepares) == 1  # the sums balance: ask everyone to confirm
    h.confirm(A)
    assert h.grants == []  # B has not confirmed
    h.confirm(B)
    assert h.grants == [(1, 3.0)]
    world = h.parts[WORLD]
    assert (world.round, world.rounds, world.has_grant()) == (1, 1, True)
    assert world.take_grant() == 3.0
    assert world.take_grant() is None  # once
    h.deliver_grant()
    assert [h.parts[i].take_grant() for i in (A, B)] == [3.0, 3.0]
    assert (h.coordinator.round, h.coordinator.rounds, h.coordinator.aborted) == (1, 1, 0)


def test_stale_reports_that_balance_are_not_granted_the_confirm_round_finds_the_change() -> None:
    # Mattern's counterexample to counting once: the sums agree while A is busy.
    h = Harness(2)
    h.idle(A, 10.0)  # A: idle, nothing sent or received
    h.send(B)  # B sends m to A...
    h.idle(B, 10.0)  # ...and reports it
    h.receive(A)  # A receives m: busy, its report is stale now
    h.send(A)  # A sends m' to the world
    h.receive(WORLD)  # which receives it...
    h.idle(WORLD, 10.0)  # ...and reports
    # sent: A 0 + B 1 + world 0 = 1; received: A 0 + B 0 + world 1 = 1. Balanced:
    assert len(h.prepares) == 1  # one round of counting would grant here
    h.confirm(A)  # "changed": A sent and received since it reported
    h.confirm(B)
    assert h.grants == []
    assert h.coordinator.aborted == 1
    h.idle(A, 2.0)  # A is done: its fresh report balances the sums for real
    assert len(h.prepares) == 2
    h.confirm(A)
    h.confirm(B)
    assert h.grants == [(1, 2.0)]


def test_a_report_arriving_while_confirming_starts_the_check_over() -> None:
    h = Harness(1)
    h.idle(WORLD, 1.0)
    h.idle(A, 1.0)
    assert len(h.prepares) == 1
    h.send(A)  # A is woken (by a thread, say) and sends before it confirms
    h.receive(WORLD)
    h.idle(WORLD, 1.0)  # the world's new report aborts the prepare
    assert h.coordinator.aborted == 1
    h.idle(A, 1.0)
    assert len(h.prepares) == 2
    h.confirm(A)
    assert h.grants == [(1, 1.0)]


def test_the_world_that_changed_since_its_report_stops_the_prepare() -> None:
    h = Harness(1)
    h.idle(WORLD, 1.0)
    h.send(A)  # A sends m to the world
    h.receive(WORLD)  # the world receives m after it reported, and answers
    h.send(WORLD)
    h.receive(A)
    h.idle(A, 1.0)  # the sums balance on A's counts alone; the world's report is stale
    assert (h.prepares, h.coordinator.aborted) == ([], 1)
    h.idle(WORLD, 1.0)
    assert len(h.prepares) == 1
    h.confirm(A)
    assert h.grants == [(1, 1.0)]


def test_rounds_advance_and_each_participant_reports_again_in_the_new_round() -> None:
    h = Harness(2)
    for until in (1.0, 2.5, 7.0):
        for ident in (WORLD, A, B):
            h.idle(ident, until if ident == B else until + 1)
        for ident in (A, B):
            h.confirm(ident)
        h.deliver_grant()
    assert h.grants == [(1, 1.0), (2, 2.5), (3, 7.0)]
    assert len(set(h.prepares)) == len(h.prepares) == 3
    assert h.coordinator.rounds == 3
    for part in h.parts.values():
        assert (part.round, part.rounds) == (3, 3)
    rounds = [report.round for ident, report in h.sent_reports if ident == A]
    assert rounds == [0, 1, 2]


def test_a_report_from_an_old_round_or_a_confirm_of_an_old_prepare_is_ignored() -> None:
    h = Harness(2)
    for ident in (WORLD, A, B):
        h.idle(ident, 1.0)
    h.confirm(A)
    h.confirm(B)
    assert h.grants == [(1, 1.0)]
    h.deliver_grant()
    h.idle(WORLD, 2.0)
    h.idle(A, 2.0)
    h.coordinator.report(B, Report(0, 2.0, 0, 0))  # late, from round 0
    h.coordinator.report(7, Report(1, 2.0, 0, 0))  # from no participant
    assert len(h.prepares) == 1  # still waiting for B's round-1 report
    h.idle(B, 2.0)
    assert len(h.prepares) == 2
    h.coordinator.confirmed(A, h.prepares[0], True)  # answers to round 0's prepare
    h.coordinator.confirmed(B, h.prepares[0], True)
    assert h.grants == [(1, 1.0)]
    h.confirm(A)
    h.confirm(B)
    assert h.grants == [(1, 1.0), (2, 2.0)]


def test_a_confirm_without_a_prepare_is_ignored() -> None:
    h = Harness(1)
    h.coordinator.confirmed(A, 0, True)
    h.idle(WORLD, 1.0)
    h.idle(A, 1.0)
    assert h.grants == []  # the early confirm did not count
    h.confirm(A)
    assert h.grants == [(1, 1.0)]


def test_when_every_deadline_is_infinite_the_grant_is_infinite_the_run_is_over() -> None:
    h = Harness(2)
    h.idle(WORLD, math.inf)
    h.idle(A, 5.0)
    h.idle(B, math.inf)
    h.confirm(A)
    h.confirm(B)
    assert h.grants == [(1, 5.0)]  # one finite deadline is enough to go on
    h.deliver_grant()
    for ident in (WORLD, A, B):
        h.idle(ident, math.inf)
    h.confirm(A)
    h.confirm(B)
    assert h.grants[-1] == (2, math.inf)


def test_participant_does_not_resend_an_identical_report() -> None:
    h = Harness(1)
    part = h.parts[A]
    assert not part.unchanged()  # nothing reported yet
    part.idle(3.0)
    part.idle(3.0)
    part.idle(3.0)
    assert [r for i, r in h.sent_reports if i == A] == [Report(0, 3.0, 0, 0)]
    assert part.unchanged()
    part.idle(2.0)  # an earlier timer appeared
    h.receive(A)
    assert not part.unchanged()
    part.idle(2.0)  # a message came in
    part.idle(2.0)
    assert [r for i, r in h.sent_reports if i == A] == [
        Report(0, 3.0, 0, 0),
        Report(0, 2.0, 0, 0),
        Report(0, 2.0, 0, 1),
    ]


def test_participant_reports_the_same_state_again_in_a_new_round_and_ignores_old_grants() -> None:
    sent: list[Report] = []
    part = Participant(A, lambda: (0, 0), lambda _ident, report: sent.append(report))
    part.idle(1.0)
    part.granted(1, 1.0)
    part.granted(1, 1.0)  # the same grant again
    part.granted(0, 9.0)  # an older one
    assert (part.round, part.rounds, part.take_grant(), part.take_grant()) == (1, 1, 1.0, None)
    part.idle(1.0)
    assert sent == [Report(0, 1.0, 0, 0), Report(1, 1.0, 0, 0)]


def test_a_late_confirm_of_an_aborted_prepare_does_not_count_for_the_next() -> None:
    # B answers prepare 1 "unchanged", then gets busy; its answer arrives only after
    # prepare 2 began (messages it caused overtook it: possible across connections,
    # e.g. workers linked directly with --listen). Counted for prepare 2, it would let
    # the world grant past B's work.
    h = Harness(3)
    h.idle(WORLD, 10.0)
    h.idle(A, 10.0)
    h.idle(C, 10.0)
    h.send(B)  # B sends m to A, and reports
    h.idle(B, 10.0)
    h.receive(A)  # A is busy with m (its report is stale) and sends m' to C
    h.send(A)
    h.receive(C)
    h.idle(C, 10.0)
    assert len(h.prepares) == 1  # stale but balanced: prepare 1
    late = (B, h.prepares[-1], h.parts[B].unchanged())  # B: "unchanged", true when sent...
    assert late[2]
    h.confirm(A)  # "changed": prepare 1 is aborted
    assert h.coordinator.aborted == 1
    h.send(A)  # A sends m'' to B, and reports
    h.idle(A, 10.0)
    h.receive(B)  # B is busy with m'' now, and sends m3 to C
    h.send(B)
    h.receive(C)
    h.idle(C, 10.0)  # the sums balance on B's stale report: prepare 2
    assert len(h.prepares) == 2
    h.coordinator.confirmed(*late)  # ...B's answer to prepare 1 arrives only now
    h.confirm(A)
    h.confirm(C)
    assert not h.parts[B].unchanged()  # B is busy
    assert h.grants == []  # B's true answer to prepare 2 ("changed") is still to come


# -- the loop ------------------------------------------------------------------------------


def _one_worker_barrier() -> tuple[Coordinator, Participant, list[float]]:
    """A coordinator whose one worker is always idle with nothing to do, answering at once."""
    granted: list[float] = []

    def grant(round_: int, until: float) -> None:
        granted.append(until)
        coordinator.report(A, Report(round_, math.inf, 0, 0))

    coordinator = Coordinator(1, lambda round_: coordinator.confirmed(A, round_, True), grant)
    coordinator.report(A, Report(0, math.inf, 0, 0))
    return coordinator, Participant(WORLD, lambda: (0, 0), coordinator.report), granted


def test_a_barrier_loop_jumps_only_to_the_instants_granted() -> None:
    coordinator, world, granted = _one_worker_barrier()
    coordinator.world = world
    seen: list[float] = []

    async def main() -> None:
        loop = asyncio.get_running_loop()
        assert isinstance(loop, BarrierLoop)
        loop.activate(world)
        await asyncio.sleep(5)
        seen.append(loop.time())
        await asyncio.sleep(2.5)
        seen.append(loop.time())

    with asyncio.Runner(loop_factory=BarrierLoop) as runner:
        runner.run(main())
    assert seen == [5.0, 7.5]
    assert granted[:2] == [5.0, 7.5]
    assert world.rounds == coordinator.rounds >= 2


def test_a_barrier_loop_stands_still_before_it_is_activated_and_stops_at_an_infinite_grant() -> (
    None
):
    coordinator, world, granted = _one_worker_barrier()
    coordinator.world = world

    async def main() -> tuple[float, float]:
        loop = asyncio.get_running_loop()
        assert isinstance(loop, BarrierLoop)
        woken = loop.create_future()
        threading.Timer(0.1, loop.call_soon_threadsafe, (woken.set_result, None)).start()
        await woken  # no timer: only the thread wakes it, and no time passes
        before = loop.time()
        loop.activate(world)
        done = loop.create_future()  # nothing scheduled: every deadline is infinite
        threading.Timer(0.2, loop.call_soon_threadsafe, (done.set_result, None)).start()
        await done
        return before, loop.time()

    with asyncio.Runner(loop_factory=BarrierLoop) as runner:
        assert runner.run(main()) == (0.0, 0.0)
    assert granted == [math.inf]
    assert world.over
