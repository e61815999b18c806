"""A stranger on the Zenoh network of a run across processes cannot stop, fool or replay it.

A world and two workers started by hand with a key file (``python -m cas_async
world`` / ``worker``), running the Fire Brigade of §5.8.2 on virtual time and on
scaled time. The stranger is a Zenoh client session in this process, connected to
the world's router, without the key. It finds the run as anyone would: one
``liveliness().get("cas_async/**")`` names the run's namespace (the world's token)
and its workers; a subscription to ``cas_async/**`` shows every key in use. Then,
while the run is under way, one probe:

* ``stray``: one garbage put under every key of the run it knows or saw;
* ``tokens``: forged liveliness tokens (``worker/0`` declared and undeclared, as if
  worker 0 had gone; ``worker/7``; ``worker/x``; the world's own);
* ``replay``: every signed control message it recorded, published again;
* ``flood``: 12,000 garbage puts under the keys the world and the workers read.

Each run must complete (every bucket), with the clean run's makespan (on virtual
time exactly, and the same ``trace.csv``: a stranger cannot change a virtual run;
on scaled time within 1.2 times), and the refusals must be in ``results.json``
(``protocol_errors``: ``control.<reason>``, and ``token.<reason>`` for the tokens).
"""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import pytest

from tests.processes_support import (
    RUN_LIMIT,
    SCENARIO,
    WORKER_EXIT_LIMIT,
    assert_all_delivered,
    control_refusals,
    free_endpoint,
    key_file,
    processes,
    read_results,
    wait_for_progress,
    wait_listening,
)

pytestmark = pytest.mark.slow  # a world, two workers and a stranger, a dozen runs

zenoh = pytest.importorskip("zenoh")

MODES: Final = {
    "virtual": ("--virtual", "--set", "mission.buckets=60"),
    "scaled": ("--set", "run.time_factor=5"),
}
"""How each run's time goes: virtual (60 buckets: about 10 wall seconds, time for every
probe), or 5 simulated seconds a wall second (20 buckets, about 5 s)."""
TARGETS: Final = {"virtual": 60, "scaled": 20}
FLOOD: Final = 12_000
SPURIOUS_REPLAYS: Final = 0
"""``control.replayed`` refusals a run counts with no stranger at all: none (a sender's
messages under two keys may come out of order; each key keeps its own count)."""
LIMIT: Final = 240
"""Wall seconds a test may take: its run and, for the first, the clean run it compares with."""
LOBBIES: dict[str, str] = {}
"""Where the workers of each run (by its namespace) ask its world to join: the world's
lobby (``cas_async/lobby/<the world's Zenoh id>/ctl/hello/``), each under its own
nonce, ``hello/<nonce>``, all of which the world reads (``hello`` alone, nobody).
Filled as the stranger finds each run."""


def lobby_hellos(namespace: str) -> str:
    """The prefix of the hellos of the run ``namespace``'s world."""
    return LOBBIES[namespace]


def strange_hello(namespace: str) -> str:
    """A hello key of the stranger's (no hex nonce: the world answers none of them)."""
    return lobby_hellos(namespace) + "stranger"


GARBAGE: Final = (
    b"",
    b"\x00",
    b"garbage",
    b"\xff" * 17,
    bytes(range(256)),
    b"\x94\xa4run!\x00\x01\xc4\x03abc",  # a msgpack array of four, like an envelope, unsigned
    b"\x91" * 2000,  # nested arrays, deep
    os.urandom(65_536),
)
"""Payloads no signed message looks like: empty, short, long, msgpack-shaped, deep, big."""


class Stranger:
    """A Zenoh client session of someone without the key, on the world's router.

    Plain ``zenoh`` calls, none of cas_async's: what anyone with the endpoint can do.
    """

    def __init__(self, endpoint: str) -> None:
        config = zenoh.Config()
        config.insert_json5("mode", '"client"')
        config.insert_json5("connect/endpoints", json.dumps([endpoint]))
        config.insert_json5("listen/endpoints", "[]")
        config.insert_json5("scouting/multicast/enabled", "false")
        self.session: Any = zenoh.open(config)
        self._lock = threading.Lock()
        self._samples: list[tuple[str, bytes]] = []
        self._declared: list[Any] = []

    def close(self) -> None:
        for declared in self._declared:
            declared.undeclare()
        self.session.close()

    def tokens(self, key_expr: str = "cas_async/**") -> list[str]:
        """The liveliness tokens under ``key_expr`` now."""
        replies = self.session.liveliness().get(key_expr, timeout=2.0)
        return sorted(str(reply.ok.key_expr) for reply in replies if reply.ok is not None)

    def namespace(self, limit: float = 20.0) -> str:
        """The run's namespace: where the world's token is (``<namespace>/world``).

        Its world's lobby is the router's this session connected to (``LOBBIES``).
        """
        deadline = time.monotonic() + limit
        while time.monotonic() < deadline:
            worlds = [key for key in self.tokens() if key.endswith("/world")]
            if worlds:
                assert len(worlds) == 1, worlds
                namespace = worlds[0].removesuffix("/world")
                (router,) = self.session.info.routers_zid()
                LOBBIES[namespace] = f"cas_async/lobby/{router}/ctl/hello/"
                return namespace
            time.sleep(0.1)
        pytest.fail(f"no world's token under cas_async/** after {limit} s")

    def record(self, key_expr: str) -> None:
        """Keeps every sample published under ``key_expr`` from now on."""

        def keep(sample: Any) -> None:
            with self._lock:
                self._samples.append((str(sample.key_expr), sample.payload.to_bytes()))

        self._declared.append(self.session.declare_subscriber(key_expr, keep))

    def recorded(self) -> list[tuple[str, bytes]]:
        with self._lock:
            return list(self._samples)

    def put(self, key: str, payload: bytes) -> None:
        """Publishes ``payload`` under ``key``, reliably (it waits rather than drop)."""
        self.session.put(key, payload, congestion_control=zenoh.CongestionControl.BLOCK)

    def hold_token(self, key: str, seconds: float) -> None:
        """Declares a liveliness token under ``key`` for ``seconds``, then undeclares it."""
        token = self.session.liveliness().declare_token(key)
        time.sleep(seconds)
        token.undeclare()


@dataclass
class Sent:
    """What a probe published, by key."""

    puts: dict[str, int] = field(default_factory=dict)
    tokens: list[str] = field(default_factory=list)

    def put(self, stranger: Stranger, key: str, payload: bytes) -> None:
        stranger.put(key, payload)
        self.puts[key] = self.puts.get(key, 0) + 1

    def refusals(self, namespace: str) -> int:
        """How many refusals these puts make: one for each process that reads the key.

        The world reads ``ctl/world``, the workers' windows ``ctl/win/*`` and the
        lobby's hellos (``hello/*``); each of the two workers reads ``ctl/all`` and ``ctl/win/*``.
        """
        return sum(n * _readers(namespace, key) for key, n in self.puts.items())

    def to_world(self, namespace: str) -> int:
        """How many of these puts the world reads."""
        return sum(n for key, n in self.puts.items() if _world_reads(namespace, key))


def _world_reads(namespace: str, key: str) -> bool:
    return key == f"{namespace}/ctl/world" or any(
        _one_chunk_under(prefix, key)
        for prefix in (f"{namespace}/ctl/win/", lobby_hellos(namespace))
    )


def _one_chunk_under(prefix: str, key: str) -> bool:
    """Whether ``key`` is ``prefix`` and one chunk more (what ``prefix*`` matches in Zenoh)."""
    rest = key.removeprefix(prefix)
    return key.startswith(prefix) and rest != "" and "/" not in rest


def _readers(namespace: str, key: str) -> int:
    """How many processes of the run read what is published under ``key``."""
    all_or_window = key == f"{namespace}/ctl/all" or _one_chunk_under(f"{namespace}/ctl/win/", key)
    workers = 2 if all_or_window else 0
    return workers + _world_reads(namespace, key)


def _run_keys(namespace: str) -> list[str]:
    """Every key of the run a stranger can name: the control plane's, and the lobby's."""
    return [
        f"{namespace}/ctl/all",
        f"{namespace}/ctl/world",
        f"{namespace}/ctl/win/0",
        f"{namespace}/ctl/win/1",
        f"{namespace}/all",
        f"{namespace}/world",
        f"{namespace}/win/0",
        strange_hello(namespace),
    ]


def stray(stranger: Stranger, namespace: str) -> Sent:
    sent = Sent()
    seen = {key for key, _ in stranger.recorded()}
    for n, key in enumerate(sorted(seen.union(_run_keys(namespace)))):
        sent.put(stranger, key, GARBAGE[n % len(GARBAGE)])
    return sent


def tokens(stranger: Stranger, namespace: str) -> Sent:
    sent = Sent()
    for name in ("worker/0", "worker/7", "worker/x", "world", "worker/1"):
        key = f"{namespace}/{name}"
        stranger.hold_token(key, 0.1)  # undeclared: to its watchers, as if it had gone
        sent.tokens.append(key)
    return sent


def replay(stranger: Stranger, namespace: str) -> Sent:
    sent = Sent()
    captured = stranger.recorded()  # the lobby's and the run's, from before the workers came
    assert captured, "the stranger saw no control message"
    for key, payload in captured[:500] + captured[max(500, len(captured) - 2500) :]:
        sent.put(stranger, key, payload)
    return sent


def flood(stranger: Stranger, namespace: str) -> Sent:
    sent = Sent()
    keys = [f"{namespace}/ctl/world", f"{namespace}/ctl/win/0", f"{namespace}/ctl/all",
            strange_hello(namespace)]  # fmt: skip
    for n in range(FLOOD):
        sent.put(stranger, keys[n % len(keys)], GARBAGE[n % (len(GARBAGE) - 1)] + n.to_bytes(4))
    return sent


Probe = Callable[[Stranger, str], Sent]
PROBES: Final[dict[str, Probe | None]] = {
    "clean": None,
    "stray": stray,
    "tokens": tokens,
    "replay": replay,
    "flood": flood,
}


@dataclass(frozen=True)
class Probed:
    """What a run with a stranger on its network did."""

    mode: str
    code: int | None
    output: str
    worker_codes: list[int | None]
    worker_outputs: list[str]
    results: dict[str, Any] | None
    trace: bytes
    namespace: str
    found: list[str]
    """The tokens the stranger's first look found."""
    sent: Sent
    during: bool
    """Whether the world still ran when the probe was over."""


def probed_run(tmp: Path, mode: str, probe: Probe | None) -> Probed:
    key, endpoint, out = key_file(tmp / "swarm.key"), free_endpoint(), tmp / "out"
    with processes(tmp / "logs") as started:
        world = started.start(
            "world", "world", SCENARIO, "--listen", endpoint, "--workers", "2",
            "--key-file", key, *MODES[mode], "--out", out, "--no-plots",
        )  # fmt: skip
        wait_listening(endpoint, world)
        stranger = Stranger(endpoint)
        try:
            namespace = stranger.namespace()
            stranger.record("cas_async/**")
            workers = [
                started.start(f"worker{k}", "worker", "--connect", endpoint, "--key-file", key)
                for k in range(2)
            ]
            wait_for_progress(world, after=0.1)  # under way
            found = stranger.tokens()
            time.sleep(0.3)  # some of the run recorded
            sent = Sent() if probe is None else probe(stranger, namespace)
            during = world.running()
            code = world.wait(RUN_LIMIT)
            worker_codes = [worker.wait(WORKER_EXIT_LIMIT) for worker in workers]
        finally:
            stranger.close()
        output = world.output()
        worker_outputs = [worker.output() for worker in workers]
    results = read_results(out) if (out / "results.json").exists() else None
    trace = (out / "trace.csv").read_bytes() if (out / "trace.csv").exists() else b""
    return Probed(mode, code, output, worker_codes, worker_outputs, results, trace, namespace,
                  found, sent, during)  # fmt: skip


@pytest.fixture(scope="module")
def run_probed(tmp_path_factory: pytest.TempPathFactory) -> Callable[[str, str], Probed]:
    """Each mode and probe's run, once per module."""
    done: dict[tuple[str, str], Probed] = {}

    def get(mode: str, probe: str) -> Probed:
        if (mode, probe) not in done:
            tmp = tmp_path_factory.mktemp(f"{mode}-{probe}")
            done[mode, probe] = probed_run(tmp, mode, PROBES[probe])
        return done[mode, probe]

    return get


CASES: Final = [
    pytest.param(mode, probe, id=f"{mode}-{probe}")
    for mode in MODES
    for probe in PROBES
    if probe != "clean"
]


def _completed(probed: Probed) -> dict[str, Any]:
    assert probed.during, f"the run ended before the probe did: it proves nothing\n{probed.output}"
    assert probed.code == 0, probed.output
    assert probed.results is not None, probed.output
    assert_all_delivered(probed.results, TARGETS[probed.mode])
    return probed.results


@pytest.mark.timeout(LIMIT)
@pytest.mark.parametrize(("mode", "probe"), CASES)
def test_the_run_completes_every_bucket(
    run_probed: Callable[[str, str], Probed], mode: str, probe: str
) -> None:
    probed = run_probed(mode, probe)
    _completed(probed)
    assert probed.worker_codes == [0, 0], probed.worker_outputs
    # What the stranger's first look found: the run, its world and both workers.
    assert f"{probed.namespace}/world" in probed.found
    assert {f"{probed.namespace}/worker/0", f"{probed.namespace}/worker/1"} <= set(probed.found)


@pytest.mark.timeout(LIMIT)
@pytest.mark.parametrize(("mode", "probe"), CASES)
def test_the_makespan_is_the_clean_runs(
    run_probed: Callable[[str, str], Probed], mode: str, probe: str
) -> None:
    clean = _completed(run_probed(mode, "clean"))
    probed = run_probed(mode, probe)
    results = _completed(probed)
    if mode == "virtual":  # the stranger cannot change a virtual run at all
        assert results["makespan"] == clean["makespan"]
        assert probed.trace == run_probed(mode, "clean").trace
    else:
        assert results["makespan"] <= 1.2 * clean["makespan"]


@pytest.mark.timeout(LIMIT)
@pytest.mark.parametrize("mode", MODES)
def test_a_stray_put_is_refused_and_counted(
    run_probed: Callable[[str, str], Probed], mode: str
) -> None:
    probed = run_probed(mode, "stray")
    refused = control_refusals(_completed(probed))
    # ctl/world, ctl/win/0 and 1, the stranger's hello and both workers'
    assert probed.sent.to_world(probed.namespace) >= 6
    # Each refused by every process that read it, and counted: none signed, none lost.
    assert refused.pop("control.unsigned") == probed.sent.refusals(probed.namespace)
    assert refused.pop("control.replayed", 0) <= SPURIOUS_REPLAYS
    assert refused == {}


@pytest.mark.timeout(LIMIT)
@pytest.mark.parametrize("mode", MODES)
def test_replayed_control_messages_are_refused_and_counted(
    run_probed: Callable[[str, str], Probed], mode: str
) -> None:
    probed = run_probed(mode, "replay")
    refused = control_refusals(_completed(probed))
    assert probed.sent.to_world(probed.namespace) > 10, probed.sent.puts
    assert f"{probed.namespace}/ctl/world" in probed.sent.puts  # Ready
    hellos = lobby_hellos(probed.namespace)
    assert any(key.startswith(hellos) for key in probed.sent.puts)  # the workers' Hellos
    # Signed, but each one's count was taken already: refused by every reader, counted.
    expected = probed.sent.refusals(probed.namespace)
    assert expected <= refused.pop("control.replayed") <= expected + SPURIOUS_REPLAYS
    assert refused == {}


@pytest.mark.timeout(LIMIT)
@pytest.mark.parametrize("mode", MODES)
def test_a_flood_is_refused_and_counted(
    run_probed: Callable[[str, str], Probed], mode: str
) -> None:
    probed = run_probed(mode, "flood")
    refused = control_refusals(_completed(probed))
    assert sum(probed.sent.puts.values()) == FLOOD
    assert refused.pop("control.unsigned") == probed.sent.refusals(probed.namespace)
    assert refused.pop("control.replayed", 0) <= SPURIOUS_REPLAYS
    assert refused == {}


@pytest.mark.timeout(LIMIT)
@pytest.mark.parametrize("mode", MODES)
def test_forged_tokens_stop_no_worker_and_lose_no_robot(
    run_probed: Callable[[str, str], Probed], mode: str
) -> None:
    probed = run_probed(mode, "tokens")
    _completed(probed)
    assert len(probed.sent.tokens) == 5
    assert "is gone" not in probed.output
    for output in probed.worker_outputs:
        assert "the world is gone" not in output
        assert "Traceback" not in output
    assert "Traceback" not in probed.output


@pytest.mark.timeout(LIMIT)
@pytest.mark.parametrize("mode", MODES)
def test_forged_tokens_are_counted_in_the_results(
    run_probed: Callable[[str, str], Probed], mode: str
) -> None:
    probed = run_probed(mode, "tokens")
    results = _completed(probed)
    errors = results["protocol_errors"]
    # worker/7 and worker/x are no process's: each seen to come (and go) by the world.
    assert errors.get("token.unknown", 0) >= 2, errors
    # The world's token went while the world held it: someone else's of that name.
    # (A forged worker/0 or worker/1 is not seen at all: the router keeps one token
    # of a name while any session declares it.)
    assert errors.get("token.forged", 0) >= 1, errors
    assert set(control_refusals(results)) <= {"control.replayed"}, errors  # no message refused
