"""The Fire Brigade over a lossy network: every bucket arrives, and hand-overs are all or nothing.

Each thesis scenario, and scale_25, runs with 10% and 30% of datagrams lost, plus duplication,
reordering and delay, in virtual time. The bucket ledger is audited after every
item event. Every Task layer's report of a meeting's end is recorded, and checked
against what physically happened (the ledger's transfers): both robots of a
hand-over report it, and a meeting reported given up moved no bucket.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from pathlib import Path

import pytest

from apps.fire_brigade.messages import CompletionStatus, MeetAt
from apps.fire_brigade.task import Task
from cas_async.sim import Environment, ItemEvent, ItemEventKind
from tests.fire_brigade.helpers import SCENARIOS, run_checked

# The thesis's scenarios and the smallest scale one (the larger ones would make this slow).
SHIPPED = sorted([*SCENARIOS.glob("thesis_*.toml"), SCENARIOS / "scale_25.toml"])


def faults(loss: float) -> list[str]:
    return [
        f"faults.loss={loss}",
        "faults.duplicate=0.05",
        "faults.reorder=0.05",
        "faults.delay=[0.0, 0.05]",
        "run.max_time=1000",
    ]


Report = tuple[int, str, int, int, bool, float]
"""A meeting's end as a Task layer reported it: (robot, status, partner, bucket, whether
the robot was the giver, the instant)."""


class Reports(list[Report]):
    """Every meeting's end; ``environment`` (set by a test) tells who held the bucket."""

    environment: Environment | None = None

    def holder_at(self, bucket: int, t: float) -> int | None:
        """Who held ``bucket`` at instant ``t``, after that instant's events (``None``:
        nobody, it was on its way or retired), from the ledger's history at the end of
        the run (the run observes its robots a window late: the ledger is complete by
        the end, up to the instant the mission was complete)."""
        assert self.environment is not None
        holder: int | None = None
        for event in self.environment.items.history(bucket):
            if event.t > t:
                break
            match event.kind:
                case ItemEventKind.CREATED | ItemEventKind.RETURNED:
                    holder = event.robot
                case ItemEventKind.TRANSFERRED:
                    holder = event.receiver
                case ItemEventKind.SENT | ItemEventKind.REFUSED | ItemEventKind.RETIRED:
                    holder = None
        return holder


Ending = Callable[[Task, MeetAt, CompletionStatus], None]
"""``Task._exchanged`` or ``Task._abandoned``: how a meeting's end is reported up the stack."""


@pytest.fixture
def reports(monkeypatch: pytest.MonkeyPatch) -> Reports:
    """Records every meeting's end, as the robot's Task layer reports it up the stack."""
    seen = Reports()

    def recording(status: str, report: Ending) -> Ending:
        def record(self: Task, plan: MeetAt, done: CompletionStatus) -> None:
            now = self.clock.now()
            seen.append((self.robot_id, status, plan.partner, plan.bucket, plan.giver, now))
            report(self, plan, done)

        return record

    monkeypatch.setattr(Task, "_exchanged", recording("Exchanged", Task._exchanged))
    monkeypatch.setattr(Task, "_abandoned", recording("Abandoned", Task._abandoned))
    return seen


@pytest.mark.parametrize("loss", [pytest.param(0.1, marks=pytest.mark.slow), 0.3])
@pytest.mark.parametrize("scenario", SHIPPED, ids=[path.stem for path in SHIPPED])
@pytest.mark.parametrize("seed", [1, pytest.param(2, marks=pytest.mark.slow)])
def test_every_scenario_delivers_every_bucket_despite_loss(
    scenario: Path, loss: float, seed: int, reports: Reports
) -> None:
    result, _, audits = run_checked(scenario, [*faults(loss), f"run.seed={seed}"])
    assert result.status.value == "completed", result.error
    assert len(result.travel_times) == result.target
    assert audits[ItemEventKind.RETIRED] == result.delivered
    assert result.faults is not None
    assert result.faults["lost"] > 0
    assert Counter(status for _, status, *_ in reports)["Exchanged"] > 0


def test_hand_overs_are_all_or_nothing(reports: Reports) -> None:
    """Both robots report each transfer, and every report agrees with who holds the bucket."""
    transfers: list[tuple[int, int, int]] = []
    times: list[float] = []
    recent: list[tuple[int, int, int]] = []  # too close to the end to be reported by both

    def watch(environment: Environment) -> None:
        reports.environment = environment

        def on_item(event: ItemEvent) -> None:
            if event.kind is ItemEventKind.TRANSFERRED:
                assert event.receiver is not None
                transfers.append((event.item, event.robot, event.receiver))
                times.append(event.t)

        environment.items.subscribe(on_item)

    # A short patience: robots give up on partners that are merely slow, too, so the
    # withdraw-and-look path runs often, racing real hand-overs.
    lossy = [*faults(0.3), "run.seed=5", "messaging.patience=2.0"]
    result, _, _ = run_checked(SCENARIOS / "thesis_5_8_2.toml", lossy, observe=watch)
    assert result.status.value == "completed", result.error
    assert any(status == "Abandoned" for _, status, *_ in reports)
    # Counted, not collected in sets: a bucket may pass through the same robot twice.
    # The robots run on a moment past the end (run.credit), unobserved: their reports
    # from then are not the run's.
    done = [r for r in reports if r[5] <= result.sim_time]
    given = Counter((r, b) for r, s, _, b, giver, _ in done if s == "Exchanged" and giver)
    taken = Counter((r, b) for r, s, _, b, giver, _ in done if s == "Exchanged" and not giver)
    # The run ends with the last delivery: a hand-over just before may not have been
    # confirmed yet (the receiver would know within patience + the Handover retries).
    settled = result.sim_time - 2.0 - 7 * 0.5
    recent.extend(x for x, t in zip(transfers, times, strict=True) if t > settled)
    assert given == Counter((giver, bucket) for bucket, giver, _ in transfers)
    assert taken.total() >= len(transfers) - len(recent)
    settled_takes = Counter((r, b) for b, g, r in transfers if (b, g, r) not in recent)
    for (receiver, bucket), n in settled_takes.items():
        assert taken[receiver, bucket] >= n, f"robot {receiver} did not report taking {bucket}"
    for robot, status, _, bucket, giver, t in reports:
        if t > result.sim_time:
            continue  # after the mission was complete: not observed
        holder = reports.holder_at(bucket, t)
        # A giver holds the bucket after a meeting given up, and not after an exchange;
        # a receiver the other way round (or its Sink retired the bucket: no holder).
        holds = holder == robot
        if giver:
            assert holds == (status == "Abandoned"), (robot, status, bucket, holder)
        elif status == "Abandoned":
            assert not holds, (robot, status, bucket, holder)
        else:
            assert holds or holder is None, (robot, status, bucket, holder)
