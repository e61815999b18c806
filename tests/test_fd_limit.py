"""ensure_descriptors: raising the soft RLIMIT_NOFILE so that sockets fit."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import textwrap
import threading
from dataclasses import dataclass, field

import pytest

from cas_async import ConfigurationError
from cas_async.transport import _fd_limit as fd_limit
from cas_async.transport._fd_limit import ensure_descriptors

INFINITY = -1  # what the fake calls RLIM_INFINITY, as Linux does


@dataclass
class FakeResource:
    """The part of the ``resource`` module ensure_descriptors uses, with a settable limit."""

    soft: int
    hard: int
    refuse_above: int | None = None  # like fs.nr_open under an infinite hard limit
    calls: list[tuple[int, int]] = field(default_factory=list)
    RLIMIT_NOFILE: int = 7
    RLIM_INFINITY: int = INFINITY

    def getrlimit(self, which: int) -> tuple[int, int]:
        assert which == self.RLIMIT_NOFILE
        return self.soft, self.hard

    def setrlimit(self, which: int, limits: tuple[int, int]) -> None:
        assert which == self.RLIMIT_NOFILE
        soft, hard = limits
        assert hard == self.hard, "the hard limit must be left as it is"
        if self.refuse_above is not None and soft > self.refuse_above:
            raise ValueError("not allowed to raise maximum limit")
        self.calls.append(limits)
        self.soft = soft


@pytest.fixture
def fake(monkeypatch: pytest.MonkeyPatch) -> FakeResource:
    """A fake resource module: 1,024 / 4,096, with 100 descriptors open."""
    resource = FakeResource(soft=1024, hard=4096)
    monkeypatch.setattr(fd_limit, "_resource", resource)
    monkeypatch.setattr(fd_limit, "_open_descriptors", lambda soft: 100)
    monkeypatch.setattr(fd_limit, "_table_size", lambda: 1 << 62)  # always count
    return resource


@pytest.mark.parametrize(
    ("soft", "hard", "needed", "expected"),
    [
        (1024, 4096, 10, 1024),  # room: nothing to do
        (1024, 4096, 412, 1024),  # exactly half the limit used: still nothing
        (1024, 4096, 413, 2048),  # past half: doubled
        (1024, 16384, 2900, 6000),  # doubling is not enough: twice what is needed
        (1024, 4096, 3996, 4096),  # up to the hard limit exactly
        (1024, 1024, 900, 1024),  # fits under a hard limit equal to the soft one
        (1024, INFINITY, 5000, 10200),
        (1024, 1500, 600, 1500),  # doubling capped by the hard limit
        (INFINITY, INFINITY, 10**9, sys.maxsize),  # unlimited
    ],
    ids=[
        "room",
        "half",
        "past-half",
        "more-than-double",
        "up-to-hard",
        "soft-is-hard",
        "infinite-hard",
        "double-capped",
        "unlimited",
    ],
)
def test_raises_the_soft_limit_as_needed(
    fake: FakeResource, soft: int, hard: int, needed: int, expected: int
) -> None:
    fake.soft, fake.hard = soft, hard
    assert ensure_descriptors(needed) == expected
    assert fake.soft == (soft if expected == sys.maxsize else expected)
    assert fake.hard == hard


def test_never_lowers_the_limit(fake: FakeResource) -> None:
    fake.soft = 3000
    assert ensure_descriptors(0) == 3000
    assert ensure_descriptors(1) == 3000
    assert fake.calls == []


def test_is_idempotent(fake: FakeResource) -> None:
    first = ensure_descriptors(1500)
    assert ensure_descriptors(1500) == first
    assert len(fake.calls) == 1


def test_too_low_a_hard_limit_is_a_clear_error(fake: FakeResource) -> None:
    with pytest.raises(ConfigurationError) as caught:
        ensure_descriptors(5000)
    text = str(caught.value)
    for part in ("5000 more", "100 open", "5100 in all", "hard limit", "4096", "ulimit -Hn 5100"):
        assert part in text
    assert "limits.conf" in text
    assert fake.soft == 1024, "a refusal changes nothing"


def test_a_kernel_cap_under_an_infinite_hard_limit_falls_back_to_what_is_needed(
    fake: FakeResource,
) -> None:
    fake.hard, fake.refuse_above = INFINITY, 1500
    assert ensure_descriptors(1300) == 1400
    fake.soft, fake.refuse_above = 1024, 1000
    with pytest.raises(ConfigurationError, match="cannot raise the soft file descriptor limit"):
        ensure_descriptors(1300)


def test_a_refused_head_start_is_no_error_when_there_is_room(fake: FakeResource) -> None:
    fake.hard, fake.refuse_above = INFINITY, 1024
    assert ensure_descriptors(500) == 1024


def test_the_table_size_spares_counting(
    fake: FakeResource, monkeypatch: pytest.MonkeyPatch
) -> None:
    def no_counting(soft: int) -> int:
        raise AssertionError("counted although the descriptor table is small")

    monkeypatch.setattr(fd_limit, "_table_size", lambda: 256)
    monkeypatch.setattr(fd_limit, "_open_descriptors", no_counting)
    assert ensure_descriptors(768) == 1024


def test_without_the_resource_module_it_does_nothing(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(fd_limit, "_resource", None)
    assert ensure_descriptors(10**9) == sys.maxsize


def test_a_negative_count_is_refused() -> None:
    with pytest.raises(ValueError, match="needed must be >= 0, got -1"):
        ensure_descriptors(-1)


def test_threads_raising_at_once_agree(fake: FakeResource) -> None:
    barrier = threading.Barrier(8)
    results: list[int] = []

    def raise_it(needed: int) -> None:
        barrier.wait()
        results.append(ensure_descriptors(needed))

    threads = [threading.Thread(target=raise_it, args=(1000 + 100 * i,)) for i in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert fake.soft == max(results) >= 1800
    soft_values = [soft for soft, _ in fake.calls]
    assert soft_values == sorted(soft_values), "a later raise lowered an earlier one"


@pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="needs /proc/self/fd")
def test_counts_the_descriptors_really_open() -> None:
    before = fd_limit._open_descriptors(1 << 20)
    sockets = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(10)]
    try:
        assert fd_limit._open_descriptors(1 << 20) == before + 10
        assert fd_limit._table_size() >= max(s.fileno() for s in sockets) + 1
    finally:
        for sock in sockets:
            sock.close()


# The real limit, lowered in a child process so that this one keeps its own.
_CHILD = textwrap.dedent(
    """
    import json, resource, socket
    from cas_async._errors import ConfigurationError
    from cas_async.transport._fd_limit import ensure_descriptors

    resource.setrlimit(resource.RLIMIT_NOFILE, (128, 600))
    from cas_async.transport._fd_limit import _open_descriptors

    out = {"first": ensure_descriptors(10), "open": _open_descriptors(128)}
    out["after_first"] = resource.getrlimit(resource.RLIMIT_NOFILE)
    out["raised"] = ensure_descriptors(200)
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(200)]
    out["again"] = ensure_descriptors(200)
    out["limit"] = resource.getrlimit(resource.RLIMIT_NOFILE)
    try:
        ensure_descriptors(1000)
    except ConfigurationError as error:
        out["error"] = str(error)
    out["final"] = resource.getrlimit(resource.RLIMIT_NOFILE)
    print(json.dumps(out))
    """
)


@pytest.mark.skipif(sys.platform == "win32", reason="no rlimits on Windows")
def test_really_raises_the_limit_in_a_child_process() -> None:
    done = subprocess.run(
        [sys.executable, "-c", _CHILD], capture_output=True, text=True, timeout=30, check=True
    )
    out = json.loads(done.stdout)
    assert out["first"] == 128
    assert out["after_first"] == [128, 600]
    # 200 more and the few open pass half of 128: twice as many as that.
    assert 2 * (out["open"] + 200) == out["raised"] < 600
    assert out["again"] == 600  # 200 sockets open and 200 more: up to the hard limit
    assert out["limit"] == [600, 600]
    assert "hard limit (RLIMIT_NOFILE) is 600" in out["error"]
    assert "ulimit -Hn" in out["error"]
    assert out["final"] == [600, 600]
