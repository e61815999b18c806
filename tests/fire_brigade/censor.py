"""A network that loses, holds back and releases chosen Fire Brigade messages on cue.

The recovery paths of the Fire Brigade (a hand-over into withdrawn hands, a
partner that never sends ``Meet``, a lost ``Handover`` notice, a message of an
earlier partnership) need the network to fail at one precise moment, which random
faults almost never produce. :class:`Censor` wraps the memory transport and shows
every datagram, decoded, to a *rule*, which returns what the wire does with it:

* :data:`DELIVER` (or ``None``): sent at once;
* :data:`DROP`: lost;
* :class:`Hold`: kept back until its ``until(now)`` is true (checked before every
  datagram sent, and every tenth of a simulated second), then sent;
* :class:`Replace`: other bytes are sent instead (what a compromised robot, or
  anyone at its address, could send).

Rules see the message with its header (sender, ``msg_type``, ``corr_id``) and the
receiver, and keep whatever state they need (``deal`` numbers tie a partnership's
messages together). :func:`run_censored` runs a scenario on it in virtual time,
auditing the bucket ledger after every item event.
"""

from __future__ import annotations

import asyncio
import contextlib
import enum
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

import numpy as np

import cas_async
from apps.fire_brigade.messages import MESSAGES
from cas_async import Clock, Message, Swarm, VirtualClock
from cas_async.scenario import SimulationSetup, load_scenario
from cas_async.sim import Environment, ItemEventKind
from cas_async.transport import Codec, DatagramSink, Endpoint, MemoryTransport, Transport
from tests.fire_brigade.helpers import VIRTUAL

__all__ = [
    "DELIVER",
    "DROP",
    "Censor",
    "Hold",
    "Outcome",
    "Replace",
    "Rule",
    "Verdict",
    "run_censored",
]

_FIRE_BRIGADE_LAYERS: Final = 5


class _Fate(enum.Enum):
    DELIVER = "deliver"
    DROP = "drop"


DELIVER: Final = _Fate.DELIVER
DROP: Final = _Fate.DROP


@dataclass(frozen=True)
class Hold:
    """Keep the datagram back until ``until(now)`` is true, then send it."""

    until: Callable[[float], bool]


@dataclass(frozen=True)
class Replace:
    """Send ``data`` in place of the datagram."""

    data: bytes


Verdict = _Fate | Hold | Replace | None
Rule = Callable[[float, int, Message], Verdict]
"""``rule(now, receiver, message) -> verdict``; the sender is ``message.robot_id``."""


@dataclass
class _Held:
    endpoint: _CensoredEndpoint
    receiver: int
    data: bytes
    until: Callable[[float], bool]


class Censor(Transport):
    """The memory transport, with ``rule`` deciding the fate of each datagram.

    Args:
        rule: see the module docs.
        clock: the robots' clock (the rule is told its time).
    """

    supports_virtual_time = True

    def __init__(self, rule: Rule, clock: Clock) -> None:
        self._inner = MemoryTransport()
        self._rule = rule
        self._clock = clock
        self._codec = Codec.for_stack(_FIRE_BRIGADE_LAYERS, MESSAGES)
        self._held: list[_Held] = []
        self.dropped = 0
        self.held = 0
        self.replaced = 0

    async def open(self, robot_id: int, sink: DatagramSink) -> Endpoint:
        return _CensoredEndpoint(self, await self._inner.open(robot_id, sink))

    def judge(self, endpoint: _CensoredEndpoint, receiver: int, data: bytes) -> None:
        """Sends, drops or holds one datagram, after sending what is due."""
        self.release_due()
        verdict = self._rule(self._clock.now(), receiver, self._codec.decode(data))
        if verdict is DROP:
            self.dropped += 1
        elif isinstance(verdict, Hold):
            self.held += 1
            self._held.append(_Held(endpoint, receiver, data, verdict.until))
        elif isinstance(verdict, Replace):
            self.replaced += 1
            endpoint.deliver(receiver, verdict.data)
        else:
            endpoint.deliver(receiver, data)

    def release_due(self) -> None:
        """Sends the held datagrams whose moment has come, in the order they were held."""
        now = self._clock.now()
        due = [held for held in self._held if held.until(now)]
        if due:
            self._held = [held for held in self._held if held not in due]
            for held in due:
                held.endpoint.deliver(held.receiver, held.data)


class _CensoredEndpoint(Endpoint):
    def __init__(self, censor: Censor, inner: Endpoint) -> None:
        self._censor = censor
        self._inner = inner
        self.robot_id = inner.robot_id
        self.max_datagram_size = inner.max_datagram_size

    @property
    def address(self) -> object:
        return self._inner.address

    def send(self, robot_id: int, data: bytes) -> None:
        if not self._inner.knows(robot_id):  # the endpoint contract: raise at once
            self._inner.send(robot_id, data)
        self._censor.judge(self, robot_id, data)

    def deliver(self, robot_id: int, data: bytes) -> None:
        with contextlib.suppress(cas_async.RobotStateError):  # closed meanwhile: lost
            self._inner.send(robot_id, data)

    def peers(self) -> Iterable[int]:
        return self._inner.peers()

    def knows(self, robot_id: int) -> bool:
        return self._inner.knows(robot_id)

    def follow_membership(self, follow: bool) -> None:
        self._inner.follow_membership(follow)

    def close(self) -> None:
        self._inner.close()


@dataclass
class Outcome:
    """What a censored run did."""

    delivered: int
    target: int
    transfers: list[tuple[float, int, int, int]] = field(default_factory=list)
    """Every hand-over: (instant, bucket, giver, receiver)."""
    ended_at: float = 0.0
    audits: int = 0
    dropped: int = 0
    held: int = 0
    replaced: int = 0
    refused: dict[int, dict[str, int]] = field(default_factory=dict)
    """What each robot's runtime dropped, by reason (``robot.dropped``)."""
    environment: Environment | None = None


def run_censored(
    scenario: Path, rule: Rule, overrides: Sequence[str] = (), *, max_time: float = 600.0
) -> Outcome:
    """Runs ``scenario`` on a :class:`Censor` in virtual time until its target (or ``max_time``).

    The bucket ledger is checked after every item event (an exchange, a delivery):
    a bucket is never in two places, never lost.
    """
    loaded = load_scenario(scenario, [*VIRTUAL, *overrides])

    async def censored() -> Outcome:
        clock = VirtualClock()
        environment = Environment()
        censor = Censor(rule, clock)
        setup = SimulationSetup(
            loaded.config,
            (loaded.world.width, loaded.world.height),
            environment,
            clock,
            censor,
            np.random.default_rng(loaded.run.seed),
        )
        mission = loaded.app.build(setup)
        ledger = environment.items
        outcome = Outcome(delivered=0, target=mission.target, environment=environment)
        complete = asyncio.Event()

        def audit(event: cas_async.sim.ItemEvent) -> None:
            ledger.check()
            outcome.audits += 1
            if event.kind is ItemEventKind.TRANSFERRED:
                assert event.receiver is not None
                outcome.transfers.append((event.t, event.item, event.robot, event.receiver))
            if ledger.retired >= mission.target:
                complete.set()

        ledger.subscribe(audit)
        async with Swarm(mission.robots) as swarm:
            running = asyncio.ensure_future(swarm.run())
            try:
                while not complete.is_set() and clock.now() < max_time:
                    assert not running.done(), running.exception()
                    await asyncio.sleep(0.1)  # simulated
                    censor.release_due()
            finally:
                running.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await running
        outcome.delivered, outcome.ended_at = ledger.retired, clock.now()
        outcome.dropped, outcome.held, outcome.replaced = (
            censor.dropped,
            censor.held,
            censor.replaced,
        )
        outcome.refused = {robot.robot_id: dict(robot.dropped) for robot in mission.robots}
        return outcome

    outcome: Outcome = cas_async.run(censored(), virtual=True)
    return outcome
