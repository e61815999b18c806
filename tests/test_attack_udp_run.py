"""A stranger on the same host floods a Fire Brigade run over real UDP, and changes nothing.

The swarm is the shipped §5.8.2 scenario (25 robots, one UDP socket each on
127.0.0.1, scaled real time). The attacker is another process, as a stranger on
the host would be: a plain socket bound to its own port on 127.0.0.1, which no
robot knows. Once the swarm is open it learns the robots' ports (what ``ss -uln``
shows anyone on the host) and sends to every one of them, 4000 datagrams a second
in all (over twice the swarm's own messages, about 14 MB/s), until the run is over.
Its datagrams come in turn from a pool the test forges with the swarm's own
:class:`~cas_async.transport.Codec`:

* ``spoofed``: well-formed messages of the Fire Brigade (``RequestInfo``,
  ``RobotInfo``, ``RequestPartner``, ``PartnerAnswer``, ``Meet``, ``MeetingPoint``,
  ``Meeting``, ``Handover``, and the internal ``MeetAt``) at their layer's level,
  whose header claims a robot of the swarm, with message ids no honest robot has
  used yet (``2**63 - 1``, ``2**64 - 1``, or minutes ahead of the clock: believed,
  one would make the claimed robot's real messages look old), some as replies to
  ids a robot may just have used, some with positions far outside the world;
* ``nan``: ``Meet``, ``RobotInfo``, ``RequestPartner``, ``RequestRobotsInRange``
  and ``RobotsInRange`` with a NaN, infinite or negative position, speed or radius;
* ``long``: datagrams of about 58 KB holding msgpack arrays of thousands of items
  (or nested thousands deep), as the whole datagram or in a field;
* ``garbage``: random bytes, cut datagrams, and messages with a made-up
  authentication trailer.

Without a swarm key, each one must be refused and counted by the robot it was
sent to as coming from an address that is no robot's (``unknown_source``), before
it is decoded: whatever it claims, the transport knows no robot at its source.
With a key, each one must be refused by the authentication (``transport.auth.*``),
before any decoding too. (What the codec makes of each forgery, were it decoded,
is checked when the pool is made; ``tests/test_fuzz_live_robot.py`` sends such
datagrams from an address the robot knows, over real UDP, where they are decoded.)
Either way the run completes with every bucket delivered and no layer failing,
and its makespan (simulated seconds: in scaled real time a loop that falls behind
lengthens it) stays within x1.5 of the same run unattacked. Refusing the flood
takes the robots' loop a few percent of a core; at this rate a refusal that cost
0.2 ms more than it does would make the makespan 2.5 times as long, one that let a
forged id through stalls the run.

The attacker reports how many of each forgery it sent to each robot, so each
robot's counts are checked exactly. The kernel drops datagrams when a robot's
receive buffer is full (none do here: the buffers hold seconds of this flood); it
counts those per socket (``/proc/net/udp``), and the checks allow for them. Run
with ``-s`` for the figures.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import math
import random
import struct
import sys
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import msgpack
import pytest

import cas_async
from apps.fire_brigade.messages import (
    MESSAGES,
    Handover,
    Kind,
    Meet,
    MeetAt,
    Meeting,
    MeetingPoint,
    PartnerAnswer,
    RequestInfo,
    RequestPartner,
    RequestRobotsInRange,
    RobotInfo,
    RobotsInRange,
)
from cas_async import (
    DecodeError,
    Message,
    MsgType,
    Robot,
    StackMismatchError,
    SwarmKey,
)
from cas_async.scenario import RunResult, RunStatus, Scenario, ScenarioRun, load_scenario
from cas_async.testing import peer_process
from cas_async.transport import Codec
from tests.wire import datagram

pytestmark = pytest.mark.slow  # whole runs over UDP under attack

SCENARIO: Final = (
    Path(__file__).resolve().parents[1] / "apps/fire_brigade/scenarios/thesis_5_8_2.toml"
)
BUCKETS: Final = 40
OVERRIDES: Final = (
    "run.transport=udp",
    "run.virtual=false",
    # At 50 the run takes about 2 wall seconds and a fifth of a core: room for the
    # flood to show if refusing it cost too much. The layers' 5 s timeouts are 100 ms.
    "run.time_factor=50",
    f"mission.buckets={BUCKETS}",
    # About 90 simulated seconds unattacked: a stalled run ends as timed out in 6 wall s.
    "run.max_time=300",
)
LAYERS: Final = 5
"""The Fire Brigade's stack: Goal, Strategy, Group Activity, Task, Action (levels 0..4)."""

RATE: Final = 4000.0
"""Datagrams per second the attacker sends, to all robots together."""
SLOWDOWN: Final = 1.5
"""Longest makespan an attacked run may have, relative to the same run unattacked."""
RUN_TIMEOUT: Final = 30.0
"""Wall seconds any run may take, whatever ``run.max_time`` (unattacked: about 2)."""
ATTACKER_LIFETIME: Final = 45.0
"""Wall seconds after which the attacker stops by itself, whatever becomes of the test."""
KEY: Final = SwarmKey(bytes(range(32)))

TOO_SHORT, FORGED = "transport.auth.too_short", "transport.auth.forged"
UNKNOWN_SOURCE: Final = "unknown_source"
FORGED_REASONS: Final = frozenset(
    {f"decode.{reason}" for reason in DecodeError.REASONS}
    | {"stack_mismatch", "spoofed_sender", "from_own_id", "unknown_source", "future_id"}
    | {"stale", "cross_level", "no_such_layer", TOO_SHORT, FORGED}
    | {"transport.auth.replay", "transport.auth.stale"}
)
"""Drop reasons a forgery could end under; the swarm's own messages never do here."""

_TRAILER: Final = struct.Struct(">qQ16s")
"""An authentication trailer: sender, counter, tag (for look-alikes)."""

# The attacker: a separate process with a plain socket, competing for the machine's
# cores as a stranger would (a thread would compete for the test's GIL instead). It
# reads the pool, says "ready", reads the robots' ports from stdin, floods at `rate`
# until stdin closes (or its lifetime ends), and prints how many of each pool entry
# it sent to each port. Every entry goes to every port in turn.
ATTACKER: Final = r"""
import json, os, select, socket, struct, sys, time

pool_path, rate, lifetime = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
deadline = time.monotonic() + lifetime
with open(pool_path, "rb") as f:
    blob = f.read()
pool, at = [], 0
while at < len(blob):
    (size,) = struct.unpack_from(">I", blob, at)
    pool.append(blob[at + 4 : at + 4 + size])
    at += 4 + size
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.bind(("127.0.0.1", 0))
sock.setblocking(False)
print("ready", flush=True)
stdin = sys.stdin.fileno()
line = b""
while not line.endswith(b"\n"):
    if not select.select([stdin], [], [], max(0.0, deadline - time.monotonic()))[0]:
        sys.exit(3)
    chunk = os.read(stdin, 4096)
    if not chunk:
        sys.exit(4)
    line += chunk
ports = [int(port) for port in line.split()]
sent = [[0] * len(ports) for _ in pool]
failed = total = 0
start = time.monotonic()
while True:
    now = time.monotonic()
    if now >= deadline or select.select([stdin], [], [], 0.0005)[0]:
        break  # stdin closed: the run is over
    for _ in range(min(int((now - start) * rate) - total, 1000)):
        entry, port = divmod(total, len(ports))
        entry %= len(pool)
        total += 1
        try:
            sock.sendto(pool[entry], ("127.0.0.1", ports[port]))
        except OSError:  # a full send buffer, or an ICMP error from a closed port
            failed += 1
        else:
            sent[entry][port] += 1
seconds = time.monotonic() - start
print(json.dumps({"sent": sent, "failed": failed, "seconds": seconds,
                  "cpu": time.process_time()}), flush=True)
"""


# -- the forgeries ---------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Forgery:
    """A forged datagram, and what a robot without a key must make of it.

    Attributes:
        kind: spoofed, nan, long or garbage (see the module docs).
        data: the datagram.
        verdict: the codec's refusal (``decode.<reason>``, ``stack_mismatch``), or
            ``"decodes"`` when it is well-formed (then its claim must be refused).
        claimed: the robot a well-formed one claims to come from.
    """

    kind: str
    data: bytes
    verdict: str
    claimed: int | None = None

    def reason_at(self, robot_id: int, *, keyed: bool) -> str:
        """Why robot ``robot_id`` must refuse this forgery."""
        if keyed:
            return TOO_SHORT if len(self.data) < _TRAILER.size else FORGED
        return UNKNOWN_SOURCE  # from the attacker's own port, which is no robot's


def verdict_of(codec: Codec, data: bytes) -> tuple[str, Message | None]:
    """What the swarm's codec makes of ``data``: the refusal's reason, or the message."""
    try:
        msg = codec.decode(data)
    except StackMismatchError:
        return "stack_mismatch", None  # counted without the "decode." prefix
    except DecodeError as exc:
        return f"decode.{exc.reason}", None
    return "decodes", msg


def pack(value: Any) -> bytes:
    data: bytes = msgpack.packb(value, use_bin_type=True)
    return data


LEVELS: Final[dict[type[Message], int]] = {
    RequestInfo: 0,
    RobotInfo: 0,
    RequestPartner: 1,
    PartnerAnswer: 1,
    RequestRobotsInRange: 1,
    RobotsInRange: 1,
    Meet: 2,
    MeetingPoint: 2,
    Meeting: 3,
    Handover: 3,
    MeetAt: 3,
}
"""The level a forgery of each message claims: where the swarm exchanges it."""


class Forger:
    """Forges datagrams for the swarm's stack, claiming robots of ``robot_ids``."""

    def __init__(self, codec: Codec, robot_ids: Sequence[int], rng: random.Random) -> None:
        self.codec = codec
        self.robot_ids = tuple(robot_ids)
        self.rng = rng
        self.now_us = time.time_ns() // 1000  # honest ids are wall microseconds
        self._long_made = 0

    def forge(self, kind: str) -> Forgery:
        data: bytes = getattr(self, kind)()
        verdict, msg = verdict_of(self.codec, data)
        return Forgery(kind, data, verdict, None if msg is None else msg.robot_id)

    def wire(self, cls: type[Message], fields: Sequence[Any]) -> bytes:
        """A datagram of ``cls`` packed by hand (the encoder would refuse NaN), header forged."""
        rng = self.rng
        ahead = self.now_us + rng.randrange(1, 600_000_000)  # up to 10 minutes ahead
        header = [
            int(rng.choice(list(MsgType))),
            rng.choice((2**63 - 1, 2**64 - 1, 2**62, ahead)),  # msg_id
            rng.choice(self.robot_ids),  # the robot it claims to come from
            LEVELS[cls],
            LEVELS[cls],
            0 if rng.random() < 0.5 else ahead - rng.randrange(2_000_000),  # corr_id
        ]
        return datagram(self.codec.fingerprint, cls, fields, header=header)

    def spoofed(self) -> bytes:
        """A well-formed message claiming a robot of the swarm; one in five outside the world."""
        rng = self.rng
        if rng.random() < 0.8:
            x, y = rng.uniform(0, 10), rng.uniform(0, 10)
        else:
            x, y = rng.choice((-1e9, 1e300, -11.0)), rng.choice((1e6, 10.5))
        kind = int(rng.choice(list(Kind)))
        deal = rng.choice((-1, self.now_us, 2**63 - 1))
        bucket, sink = rng.randrange(100), rng.randrange(1, 26)
        choices: dict[type[Message], list[Any]] = {
            RequestInfo: [],
            RobotInfo: [x, y, kind, rng.uniform(0, 5)],
            RequestPartner: [x, y, kind, bucket, [sink, x, y]],
            PartnerAnswer: [kind],
            Meet: [x, y, kind, rng.uniform(0, 5), deal],
            MeetingPoint: [x, y, deal],
            Meeting: [deal],
            Handover: [bucket, deal],
            MeetAt: [sink, x, y, True, bucket, [sink, x, y], deal],
        }
        cls = rng.choice(list(choices))
        return self.wire(cls, choices[cls])

    def nan(self) -> bytes:
        """A well-formed message but for one value outside its bounds."""
        rng = self.rng
        x, y = rng.uniform(0, 10), rng.uniform(0, 10)
        bad = rng.choice((math.nan, math.inf, -math.inf))
        speed = rng.choice((math.nan, math.inf, -1.0))  # a speed may not be negative either
        choices: list[tuple[type[Message], list[Any]]] = [
            (Meet, [x, y, 2, speed, -1]),
            (Meet, [bad, y, 2, 1.0, -1]),
            (RobotInfo, [x, y, 2, speed]),
            (RequestPartner, [x, bad, 2, -1, [-1, x, y]]),
            (RequestRobotsInRange, [speed]),  # the radius
            (RobotsInRange, [[1, 2], [x, bad], [y, y], x, y, 1.0]),
        ]
        cls, fields = rng.choice(choices)
        return self.wire(cls, fields)

    def long(self) -> bytes:
        """About 58 KB of msgpack arrays of thousands of items, which no field takes."""
        rng = self.rng
        n = rng.randrange(6300, 6500)  # items of 9 bytes each (float64, uint64)
        big = 2**40
        choice = self._long_made % 6  # each in turn
        self._long_made += 1
        if choice == 0:  # the whole datagram: an array of floats, no header at all
            return pack([rng.random() for _ in range(n)])
        if choice == 1:  # an array of ints, as a header of some other stack would start
            return pack(list(range(big, big + n)))
        if choice == 2:  # in an int field
            return self.wire(Meeting, [list(range(big, big + n))])
        if choice == 3:  # a list of coordinates, the last one NaN
            xs = [rng.uniform(0, 10) for _ in range(n)] + [math.nan]
            return self.wire(RobotsInRange, [[1], xs, [1.0], 1.0, 1.0, 1.0])
        if choice == 4:  # a list of ids that are strings (6 bytes each)
            ids = ["robot"] * (n * 3 // 2)
            return self.wire(RobotsInRange, [ids, [], [], 1.0, 1.0, 1.0])
        # in an int field, arrays in arrays, 9 * n deep
        marker = 2**64 - 7  # packed as 9 bytes no other value of the datagram has
        data = self.wire(Meeting, [marker])
        return data.replace(pack(marker), b"\x91" * (9 * n) + b"\x00")

    def garbage(self) -> bytes:
        """Random bytes, a cut datagram, or a message with a made-up authentication trailer."""
        rng = self.rng
        choice = rng.randrange(3)
        if choice == 0:
            return rng.randbytes(rng.randrange(1500))
        if choice == 1:
            data = self.spoofed()
            return data[: rng.randrange(len(data))]
        trailer = _TRAILER.pack(rng.choice(self.robot_ids), 2**64 - 1, rng.randbytes(16))
        return self.spoofed() + trailer


POOL: Final = {"spoofed": 50, "nan": 30, "long": 6, "garbage": 14}
"""Forgeries of each kind in the pool. A run sends each to each robot a few times; the
long ones are 6% of the datagrams and about 60% of the bytes."""


def forge_pool(robot_ids: Sequence[int], seed: int) -> list[Forgery]:
    """The attacker's pool, shuffled; checks that each forgery is what its kind says."""
    forger = Forger(Codec.for_stack(LAYERS, MESSAGES), robot_ids, random.Random(seed))
    pool = [forger.forge(kind) for kind, count in POOL.items() for _ in range(count)]
    random.Random(seed).shuffle(pool)
    for forgery in pool:
        if forgery.kind == "spoofed":  # it would be taken, were its claim believed
            assert forgery.verdict == "decodes", forgery
            assert forgery.claimed in robot_ids, forgery
        elif forgery.kind == "nan":
            assert forgery.verdict == "decode.out_of_range", forgery
        elif forgery.kind == "long":  # refused by decoding, not after
            assert 50_000 < len(forgery.data) <= 65_507, len(forgery.data)  # UDP carries it
            assert forgery.verdict != "decodes", forgery
    return pool


def write_pool(pool: Sequence[Forgery], path: Path) -> None:
    with path.open("wb") as out:
        for forgery in pool:
            out.write(struct.pack(">I", len(forgery.data)) + forgery.data)


# -- a run, attacked or not ------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Attack:
    """What the attacker did, as it reported it."""

    sent: list[list[int]]
    """How many of pool entry ``e`` it sent to the robot at index ``r``: ``sent[e][r]``."""
    failed: int
    seconds: float
    cpu: float

    @property
    def total(self) -> int:
        return sum(map(sum, self.sent))


@dataclass(frozen=True, slots=True)
class Outcome:
    """One run: what it measured, and what each robot dropped."""

    result: RunResult
    run_wall: float
    """Wall seconds from building the robots until the run ended (before they stop)."""
    robot_ids: list[int]
    dropped: list[Counter[str]]
    """What each robot dropped, by reason, in the order of ``robot_ids``."""
    kernel_drops: list[int] | None
    """Datagrams the kernel dropped at each robot's socket (``None``: cannot tell)."""
    attack: Attack | None
    unaccounted: int
    """Forgeries sent that neither a robot nor the kernel counted (after a bounded wait)."""

    @property
    def robot_drops(self) -> Counter[str]:
        """What the swarm dropped, by reason."""
        return sum(self.dropped, Counter())


def kernel_drops(ports: Sequence[int]) -> list[int] | None:
    """Per port, datagrams the kernel dropped at the 127.0.0.1 socket bound to it (Linux)."""
    try:
        lines = Path("/proc/net/udp").read_text().splitlines()[1:]
    except OSError:
        return None
    drops: dict[int, int] = {}
    for line in lines:
        fields = line.split()
        host, port = fields[1].split(":")
        if host == "0100007F":  # 127.0.0.1, little-endian hex
            drops[int(port, 16)] = int(fields[-1])
    return [drops.get(port, 0) for port in ports]


def forged_drops(robots: Sequence[Robot]) -> int:
    """Datagrams the robots refused for a reason only a forgery has here."""
    return sum(
        n for robot in robots for reason, n in robot.dropped.items() if reason in FORGED_REASONS
    )


def attacker(pool_file: Path) -> contextlib.AbstractAsyncContextManager[asyncio.subprocess.Process]:
    """The attacker's process, once it is ready; killed and reaped on the way out."""
    argv = (sys.executable, "-c", ATTACKER, str(pool_file), str(RATE), str(ATTACKER_LIFETIME))
    return peer_process(*argv, timeout=20.0)


async def stop_attacker(proc: asyncio.subprocess.Process) -> Attack:
    assert proc.stdin is not None
    assert proc.stdout is not None
    proc.stdin.close()
    report = json.loads(await asyncio.wait_for(proc.stdout.readline(), 10))
    await asyncio.wait_for(proc.wait(), 10)
    return Attack(report["sent"], report["failed"], report["seconds"], report["cpu"])


async def until(condition: Callable[[], bool], seconds: float) -> None:
    """Polls ``condition`` while the robots read what is still queued (bounded, no assert)."""
    with contextlib.suppress(TimeoutError):
        async with asyncio.timeout(seconds):
            while not condition():
                await asyncio.sleep(0.01)


async def run(scenario: Scenario, *, key: SwarmKey | None, pool_file: Path | None) -> Outcome:
    """Runs ``scenario`` to its end, flooded from ``pool_file`` when given."""
    async with contextlib.AsyncExitStack() as stack:
        proc = None
        if pool_file is not None:  # ready before the run starts: the flood starts with it
            proc = await stack.enter_async_context(attacker(pool_file))
        scenario_run = ScenarioRun(scenario, key=key)
        async with scenario_run:
            robots = list(scenario_run.swarm)
            ports = []
            for robot in robots:
                address = robot.address
                assert isinstance(address, tuple)  # UDP: (host, port)
                ports.append(address[1])
            if proc is not None:  # the flood starts as the robots do
                assert proc.stdin is not None
                proc.stdin.write(" ".join(map(str, ports)).encode() + b"\n")
                await proc.stdin.drain()
            result = await asyncio.wait_for(scenario_run.until_done(), RUN_TIMEOUT)
            run_wall = result.wall_time
            attack = None if proc is None else await stop_attacker(proc)
            sent = 0 if attack is None else attack.total

            def unaccounted() -> int:
                return sent - forged_drops(robots) - sum(kernel_drops(ports) or [0])

            # The robots still run: they read what the attacker queued last.
            await until(lambda: unaccounted() <= 0, 5)
            return Outcome(
                result,
                run_wall,
                [robot.robot_id for robot in robots],
                [Counter(robot.dropped) for robot in robots],
                kernel_drops(ports),
                attack,
                unaccounted(),
            )


def runs(scenario: Scenario, pool_file: Path, key: SwarmKey | None) -> tuple[Outcome, Outcome]:
    """The run unattacked, then attacked: each on a loop of its own, as the CLI runs it."""
    baseline = cas_async.run(run(scenario, key=key, pool_file=None), virtual=False)
    attacked = cas_async.run(run(scenario, key=key, pool_file=pool_file), virtual=False)
    return baseline, attacked


# -- the checks ------------------------------------------------------------------------------


def describe(label: str, outcome: Outcome, pool: Sequence[Forgery]) -> None:
    result = outcome.result
    print(
        f"\n{label}: {result.status}, makespan {result.makespan} s, {outcome.run_wall:.2f} "
        f"wall s, {result.delivered}/{result.target} delivered, "
        f"{sum(result.messages_external.values())} messages sent, "
        f"kernel drops {sum(outcome.kernel_drops or [0])}"
    )
    attack = outcome.attack
    if attack is not None:
        by_kind: Counter[str] = Counter()
        for forgery, counts in zip(pool, attack.sent, strict=True):
            by_kind[forgery.kind] += sum(counts)
        megabytes = sum(len(f.data) * sum(c) for f, c in zip(pool, attack.sent, strict=True)) / 1e6
        print(
            f"  attacker: {attack.total} datagrams ({dict(by_kind)}), {megabytes:.0f} MB in "
            f"{attack.seconds:.2f} s ({attack.total / attack.seconds:.0f}/s, "
            f"{attack.cpu:.2f} CPU s), {attack.failed} failed to send"
        )
    print(f"  dropped: {dict(outcome.robot_drops.most_common())}")


def check_completed(outcome: Outcome, baseline: Outcome) -> None:
    """The run did its job, no later than x1.5 the unattacked one."""
    result = outcome.result
    assert result.status is RunStatus.COMPLETED, (result.status, result.error, result.traceback)
    assert result.error is None
    # On real time a bucket may still arrive while the swarm is being stopped.
    assert result.delivered >= result.target == BUCKETS
    assert result.makespan is not None
    assert baseline.result.makespan is not None
    assert result.makespan <= SLOWDOWN * baseline.result.makespan, (
        f"attacked makespan {result.makespan:.1f} s, unattacked {baseline.result.makespan:.1f} s"
    )


def check_refused(outcome: Outcome, pool: Sequence[Forgery], *, keyed: bool) -> None:
    """Each forgery sent to a robot was counted there under its reason (or by the kernel)."""
    attack = outcome.attack
    assert attack is not None
    # The flood was one: the attacker kept its rate through the run, and sent every
    # forgery of the pool to every robot.
    assert attack.seconds >= 0.5 * outcome.run_wall, (attack.seconds, outcome.run_wall)
    assert attack.total >= 0.8 * RATE * attack.seconds, (attack.total, attack.seconds)
    assert attack.failed <= 0.01 * attack.total, attack.failed
    assert all(all(row) for row in attack.sent), "the run ended before the pool was sent"
    assert outcome.unaccounted <= 0, f"{outcome.unaccounted} forgeries were never counted"
    kernel = outcome.kernel_drops or [0] * len(outcome.robot_ids)
    for index, robot_id in enumerate(outcome.robot_ids):
        expected: Counter[str] = Counter()
        for forgery, counts in zip(pool, attack.sent, strict=True):
            expected[forgery.reason_at(robot_id, keyed=keyed)] += counts[index]
        counted = outcome.dropped[index]
        # Exact, unless the kernel dropped some: then short by at most what it dropped.
        for reason in FORGED_REASONS:
            assert expected[reason] - kernel[index] <= counted[reason] <= expected[reason], (
                f"robot {robot_id}, {reason}: counted {counted[reason]}, "
                f"sent {expected[reason]} (kernel drops {kernel[index]})"
            )


def check_logs(caplog: pytest.LogCaptureFixture) -> None:
    """No exception escaped a callback (asyncio logs them), and the drop logs stayed short."""
    ours = [r for r in caplog.records if r.name.startswith("cas_async")]
    crashes = [r for r in caplog.records if r.levelno >= logging.ERROR and r not in ours]
    assert crashes == [], crashes[0].getMessage()
    print(f"  log records: {len(ours)}")
    assert len(ours) < 2000, Counter(r.getMessage()[:60] for r in ours).most_common(5)


@pytest.fixture(scope="module")
def scenario() -> Scenario:
    return load_scenario(SCENARIO, OVERRIDES)


@pytest.fixture(scope="module")
def robot_ids(scenario: Scenario) -> list[int]:
    """The swarm's robots: numbered from 1 (what the attacker forges claims of)."""
    return list(range(1, sum(scenario.app.robots(scenario.config).values()) + 1))


def test_without_a_key_a_stranger_is_refused_before_decoding_and_the_run_keeps_its_pace(
    scenario: Scenario, robot_ids: list[int], tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING)
    pool = forge_pool(robot_ids, seed=8)
    write_pool(pool, tmp_path / "pool")
    baseline, attacked = runs(scenario, tmp_path / "pool", key=None)
    describe("unattacked", baseline, pool)
    describe("attacked", attacked, pool)
    assert attacked.robot_ids == robot_ids
    check_completed(baseline, baseline)
    check_completed(attacked, baseline)
    check_refused(attacked, pool, keyed=False)
    assert attacked.robot_drops[UNKNOWN_SOURCE] > 0  # the checks above cannot be empty
    # Refused before decoding: nothing reached the codec or the sender checks.
    assert not [r for r in attacked.robot_drops if r.startswith("decode.")]
    assert attacked.robot_drops["spoofed_sender"] == attacked.robot_drops["stack_mismatch"] == 0
    # No forged id got far enough to make a real message look old.
    assert attacked.robot_drops["stale"] == attacked.robot_drops["future_id"] == 0
    check_logs(caplog)


def test_with_a_key_forgeries_are_refused_before_decoding(
    scenario: Scenario, robot_ids: list[int], tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING)
    pool = forge_pool(robot_ids, seed=9)
    write_pool(pool, tmp_path / "pool")
    baseline, attacked = runs(scenario, tmp_path / "pool", key=KEY)
    describe("unattacked, with a key", baseline, pool)
    describe("attacked, with a key", attacked, pool)
    assert attacked.robot_ids == robot_ids
    check_completed(baseline, baseline)
    check_completed(attacked, baseline)
    check_refused(attacked, pool, keyed=True)
    # Refused before decoding: not one reached the codec or the header checks.
    assert set(attacked.robot_drops) & FORGED_REASONS == {TOO_SHORT, FORGED}
    check_logs(caplog)
