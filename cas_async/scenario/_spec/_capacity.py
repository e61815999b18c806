"""How many robots this machine can hold: a scenario's sizes are checked before anything is built.

An application says how many robots a configuration builds, by the key that sets
each number (``SimulationApp.robots``); the loader compares the total with what
the machine has, so that ``count = 1000000000000`` fails at once, naming the key,
instead of building until memory runs out:

* memory: about :data:`ROBOT_MEMORY` per robot (measured: the 11,600 robots of
  the Fire Brigade's ``scale_10000`` peak at 1.1 GB over a whole run), plus the
  trace of a run that lasts until ``max_time``, against the memory available now
  (``MemAvailable``, within the control group's limit);
* with the UDP transport, one socket per robot: a file descriptor each (up to the
  hard ``RLIMIT_NOFILE``, to which the soft limit is raised as robots open) and a
  local port each (``net.ipv4.ip_local_port_range``).

A limit that cannot be read is not checked.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from ...transport._fd_limit import descriptor_room

__all__ = ["ROBOT_MEMORY", "Capacity", "capacity_problems", "processes_problem"]

ROBOT_MEMORY: Final = 100 * 1024
"""Bytes a robot takes at its peak over a run, with its share of the messages in flight."""
SAMPLE_MEMORY: Final = 16
"""Bytes a robot's position takes in each sample of the trace."""


@dataclass(frozen=True, slots=True)
class Capacity:
    """What a machine can give a swarm; ``None`` where it cannot be told.

    Attributes:
        memory: bytes available to this process now.
        descriptors: file descriptors this process can still open.
        descriptor_limit: the hard ``RLIMIT_NOFILE`` (for the message).
        ports: local ports the kernel hands out to sockets bound to port 0.
    """

    memory: int | None = None
    descriptors: int | None = None
    descriptor_limit: int | None = None
    ports: int | None = None

    @classmethod
    def of_this_machine(cls) -> Capacity:
        """What this process can have now (read from ``/proc`` and ``/sys`` on Linux)."""
        room, hard = descriptor_room()
        unlimited = hard >= 2**62
        return cls(
            memory=_available_memory(),
            descriptors=None if unlimited else room,
            descriptor_limit=None if unlimited else hard,
            ports=_local_ports(),
        )


def capacity_problems(
    counts: Mapping[str, int],
    transport: str,
    capacity: Capacity,
    samples: float = 0,
    processes: int = 1,
) -> list[tuple[str, str]]:
    """The problems, as ``(key, message)``, of running ``counts`` robots on ``capacity``.

    Args:
        counts: robots by the key that sets their number (``{"transporters.count": 16}``).
        transport: ``"udp"`` needs a socket per robot; other transports do not.
        capacity: what the machine can give.
        samples: trace samples a run reaching ``run.max_time`` takes (``max_time /
            trace_interval``); each holds every robot's position.
        processes: processes on this machine that each build every robot (a run
            across processes: the world and its workers).

    Returns:
        At most one problem per limit, named after the key with the most robots
        (``run.trace_interval`` when the trace would take more memory than the robots).
    """
    total = sum(counts.values())
    if not counts or total <= 0:
        return []
    key = max(counts, key=lambda name: counts[name])
    many = f"{_number(counts[key])} robots"
    if len(counts) > 1:
        many += f" ({_number(total)} in all)"
    problems = []
    robots = total * ROBOT_MEMORY * processes
    trace = total * samples * SAMPLE_MEMORY
    if capacity.memory is not None and robots + trace > capacity.memory:
        have = f"this machine has {_bytes(capacity.memory)} available"
        if trace > robots:
            problems.append(
                (
                    "run.trace_interval",
                    f"a trace of {_number(samples)} samples (run.max_time / run.trace_interval) "
                    f"of {_number(total)} robots needs about {_bytes(trace)}; {have}: sample less "
                    "often or set a shorter max_time",
                )
            )
        else:
            most = capacity.memory // (ROBOT_MEMORY * processes)
            where = (
                f" in each of {processes} processes (the world and its workers each build "
                "every robot)"
                if processes > 1
                else ""
            )
            problems.append(
                (
                    key,
                    f"{many} need about {_bytes(robots)} at about {_bytes(ROBOT_MEMORY)} "
                    f"each{where}; {have}: at most about {most:,} robots"
                    + (", or fewer processes" if processes > 1 else ""),
                )
            )
    if transport == "udp":
        if capacity.descriptors is not None and total > capacity.descriptors:
            problems.append(
                (
                    key,
                    f"{many} need a UDP socket each; this process may open "
                    f"{capacity.descriptors:,} more files (hard limit "
                    f"{capacity.descriptor_limit:,}; raise it with ulimit -Hn), "
                    'or use transport = "memory"',
                )
            )
        if capacity.ports is not None and total > capacity.ports:
            problems.append(
                (
                    key,
                    f"{many} need a local UDP port each; the kernel hands out "
                    f"{capacity.ports:,} (net.ipv4.ip_local_port_range), "
                    'so run them in several processes or use transport = "memory"',
                )
            )
    return problems


def processes_problem(
    counts: Mapping[str, int], workers: int, capacity: Capacity, samples: float = 0
) -> str | None:
    """Why ``workers`` worker processes cannot run ``counts`` robots here, or ``None``.

    More workers than robots, or more than memory holds: the world and every
    worker each build every robot.
    """
    total = sum(counts.values())
    if workers > total:
        return f"{workers} worker processes for {total} robots: at most {total} (one robot each)"
    problems = capacity_problems(counts, "memory", capacity, samples, processes=workers + 1)
    if problems:
        key, problem = problems[0]
        return f"{key}: {problem}"
    return None


def _number(n: float) -> str:
    """``12,345`` up to a quadrillion, ``1.2e+23`` beyond."""
    return f"{n:,.0f}" if n < 1e15 else f"{n:.2g}"


def _bytes(n: float) -> str:
    """``n`` bytes in the largest unit that keeps a number of at least 1: ``93.1 TiB``."""
    value = float(n)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"):
        if value < 1024 or unit == "EiB":
            if unit == "B":
                return f"{value:,.0f} B"
            return f"{value:,.1f} {unit}" if value < 1e6 else f"{_number(value)} {unit}"
        value /= 1024
    raise AssertionError("unreachable")


def _available_memory() -> int | None:
    """Bytes this process can still take: ``MemAvailable``, within its cgroup's limit."""
    available = _meminfo_available()
    if available is None:
        try:
            available = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (AttributeError, OSError, ValueError):
            available = None
    room = _cgroup_room()
    if room is not None:
        available = room if available is None else min(available, room)
    return available


def _meminfo_available() -> int | None:
    try:
        with open("/proc/meminfo", encoding="ascii") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _cgroup_room() -> int | None:
    """``memory.max - memory.current`` of this process's cgroup (v2), when limited."""
    try:
        lines = Path("/proc/self/cgroup").read_text(encoding="ascii").splitlines()
        path = next(line[3:] for line in lines if line.startswith("0::"))
        folder = Path("/sys/fs/cgroup") / path.lstrip("/")
        limit = (folder / "memory.max").read_text(encoding="ascii").strip()
        if limit == "max":
            return None
        used = int((folder / "memory.current").read_text(encoding="ascii"))
        return max(0, int(limit) - used)
    except (OSError, ValueError, StopIteration):
        return None


def _local_ports() -> int | None:
    try:
        text = Path("/proc/sys/net/ipv4/ip_local_port_range").read_text(encoding="ascii")
        low, high = (int(part) for part in text.split())
    except (OSError, ValueError):
        return None
    return max(0, high - low + 1)
