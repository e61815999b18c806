"""Shared pieces of the benchmarks: the typical message, the runner, the report.

Every benchmark measures the framework and a hand-written baseline in the same
process, alternating (the side that goes first swaps every run), each side in a
fresh event loop, and reports the median of the runs. The result is one line of
a table and exactly one JSON line (per loop) on stdout; progress goes to stderr.
"""

from __future__ import annotations

import argparse
import asyncio
import ctypes
import importlib
import json
import statistics
import sys
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass

import msgpack

from cas_async import Message, loop_factory, uvloop_available
from cas_async.transport import Codec

from ._table import print_aligned

LOOPBACK = "127.0.0.1"
SOCKET_BUFFER = 4 * 1024 * 1024  # what UdpTransport asks for; the baselines ask the same
WAIT_LIMIT = 60.0  # seconds any one measurement may take before it is abandoned


class Sample(Message):
    """The typical message: 2 floats, an int, a bool, a short str, 10 ints."""

    x: float
    y: float
    n: int
    ok: bool
    name: str
    values: list[int]


class Ack(Message):
    """Flow control: how many messages the receiver has seen so far."""

    count: int


MESSAGES = [Sample, Ack]
VALUES = list(range(10))
SAMPLE_TAG = Sample.__struct_config__.tag
ACK_TAG = Ack.__struct_config__.tag
# The fingerprint of a one-layer robot with MESSAGES, which every datagram begins
# with: the raw sides just carry it.
RAW_PREFIX = Codec(1, MESSAGES).fingerprint.to_bytes(4, "big")
PREFIX = len(RAW_PREFIX)
N_AT, ID_AT, COUNT_AT = 3, 8, 1  # where a raw Sample's n and msg_id are, and an Ack's count


def sample(n: int) -> Sample:
    return Sample(1.5, -2.25, n, True, "robot-7", VALUES)


def raw_sample(n: int, robot_id: int = 1, corr_id: int = 0) -> list[object]:
    """What the framework puts on the wire for ``sample(n)``, as a plain list.

    The raw baselines send the same tag, the same 6 fields and the same 6 header
    ints (msg_type, msg_id, robot_id, src_layer, dst_layer, corr_id) behind the
    same fingerprint (:func:`raw_pack`), so both sides move the same bytes and
    only the framework's overhead differs.
    """
    return [SAMPLE_TAG, 1.5, -2.25, n, True, "robot-7", VALUES,
            1, n, robot_id, 0, 0, corr_id]  # fmt: skip


def raw_ack(count: int, robot_id: int = 2) -> list[object]:
    return [ACK_TAG, count, 1, count, robot_id, 0, 0, 0]


def raw_pack(values: list[object]) -> bytes:
    """A raw datagram: the fingerprint, then the values packed by ``msgpack.packb``."""
    return RAW_PREFIX + msgpack.packb(values)


def raw_unpack(data: bytes) -> list[object]:
    """The values of a raw datagram (``msgpack.unpackb`` after the fingerprint)."""
    values: list[object] = msgpack.unpackb(data[PREFIX:])
    return values


# A measurement gets the problem size and returns one figure (see Bench.unit).
Measure = Callable[[int], Awaitable[float]]


@dataclass(frozen=True)
class Bench:
    """One comparison: framework against baseline, and the ratio the target bounds."""

    name: str
    unit: str
    framework: Measure
    baseline: Measure
    size: int  # messages or iterations per measurement
    quick_size: int
    target: float  # on framework / baseline
    higher_is_better: bool = True  # False for latencies: ratio <= target passes

    def passed(self, ratio: float) -> bool:
        return ratio >= self.target if self.higher_is_better else ratio <= self.target


def pin_malloc() -> bool:
    """Fixes glibc's malloc thresholds so every run allocates the same way.

    The stdlib loop receives each datagram into a fresh 256 KiB buffer. With glibc's
    default *dynamic* mmap threshold, whether that buffer costs an mmap + mremap +
    munmap (about 36k datagrams/s on this machine) or comes from the heap (about
    150k/s) depends on what the process freed before, so either side of a comparison
    may land in the slow mode by chance. Pinning the thresholds above 256 KiB keeps
    every run on the heap. Returns False where ``mallopt`` is unavailable.
    """
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    m_trim_threshold, m_mmap_threshold = -1, -3
    return bool(mallopt(m_mmap_threshold, 1 << 20) and mallopt(m_trim_threshold, 8 << 20))


def measure_once(fn: Measure, size: int, use_uvloop: bool) -> float:
    runner = asyncio.Runner(loop_factory=loop_factory(use_uvloop=use_uvloop))
    with runner:
        return runner.run(asyncio.wait_for(fn(size), WAIT_LIMIT))


def run_bench(bench: Bench, loop: str, runs: int, quick: bool) -> dict[str, object]:
    size = bench.quick_size if quick else bench.size
    sides = {"framework": bench.framework, "baseline": bench.baseline}
    results: dict[str, list[float]] = {"framework": [], "baseline": []}
    for run in range(runs):
        order = ["baseline", "framework"] if run % 2 == 0 else ["framework", "baseline"]
        for side in order:
            value = measure_once(sides[side], size, loop == "uvloop")
            results[side].append(value)
            print(
                f"  {bench.name} {loop} run {run + 1}: {side} {value:,.1f} {bench.unit}",
                file=sys.stderr,
            )
    framework = statistics.median(results["framework"])
    baseline = statistics.median(results["baseline"])
    ratio = framework / baseline
    return {
        "benchmark": bench.name,
        "loop": loop,
        "unit": bench.unit,
        "framework": round(framework, 2),
        "baseline": round(baseline, 2),
        "ratio": round(ratio, 3),
        "target": f"{'>=' if bench.higher_is_better else '<='} {bench.target}",
        "passed": bench.passed(ratio),
        "runs": runs,
        "size": size,
        "framework_runs": [round(v, 2) for v in results["framework"]],
        "baseline_runs": [round(v, 2) for v in results["baseline"]],
    }


def print_table(rows: Sequence[dict[str, object]]) -> None:
    header = ("benchmark", "loop", "framework", "baseline", "unit", "ratio", "target", "pass")
    lines = [header]
    for r in rows:
        numbers = (f"{r['framework']:,.1f}", f"{r['baseline']:,.1f}", str(r["unit"]))
        verdict = "PASS" if r["passed"] else "FAIL"
        lines.append((str(r["benchmark"]), str(r["loop"]), *numbers, f"{r['ratio']:.3f}",
                      str(r["target"]), verdict))  # fmt: skip
    print_aligned(lines, left=(0, 1))


def main(benches: Sequence[Bench], argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="cas_async benchmarks: framework vs raw asyncio")
    parser.add_argument("--quick", action="store_true", help="smaller sizes (a smoke test)")
    parser.add_argument("--runs", type=int, default=3, help="runs per side (default 3)")
    parser.add_argument("--loop", choices=["stdlib", "uvloop", "both"], default="both")
    parser.add_argument("--only", action="append", help="run only this benchmark (repeatable)")
    parser.add_argument(
        "--malloc",
        choices=["pinned", "default"],
        default="pinned",
        help="pinned (default): fixed glibc thresholds, see pin_malloc; default: glibc's own",
    )
    args = parser.parse_args(argv)
    if args.runs < 1:
        parser.error("--runs must be at least 1")
    malloc = "pinned" if args.malloc == "pinned" and pin_malloc() else "default"
    loops = ["stdlib", "uvloop"] if args.loop == "both" else [args.loop]
    if "uvloop" in loops and not uvloop_available():
        print("uvloop is not installed: skipping it", file=sys.stderr)
        loops.remove("uvloop")
    selected = [b for b in benches if not args.only or b.name in args.only]
    if not selected:
        parser.error(f"--only: choose among {', '.join(b.name for b in benches)}")
    rows = [run_bench(b, loop, args.runs, args.quick) for loop in loops for b in selected]
    for row in rows:
        row["malloc"] = malloc
    print()
    print_table(rows)
    print()
    for row in rows:
        print(json.dumps(row))
    return 0 if all(r["passed"] for r in rows) else 1


@dataclass(frozen=True, slots=True)
class OptionalPackage:
    """A package some benches need: whether it imports, and what to say when it does not.

    Attributes:
        missing: why it cannot be imported, ``None`` when it can.
        benches: the benches that need it.
        extra: the pyproject extra that installs it.
    """

    missing: str | None
    benches: tuple[str, ...]
    extra: str

    @classmethod
    def probe(
        cls, module: str, package: str, benches: Sequence[str], extra: str
    ) -> OptionalPackage:
        """Imports ``module`` once (``package`` is its distribution's name, for the message)."""
        try:
            importlib.import_module(module)
        except ImportError as exc:
            return cls(f"{package} is not importable ({exc})", tuple(benches), extra)
        return cls(None, tuple(benches), extra)

    def skip_message(self) -> str:
        """Why the benches are skipped, for the caller to print (empty when they are not)."""
        if self.missing is None:
            return ""
        return (
            f"skipping {', '.join(self.benches)}: {self.missing}; pip install -e '.[{self.extra}]'"
        )
