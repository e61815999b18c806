"""What the machine can hold: absurd sizes are refused before anything is built."""

from __future__ import annotations

from pathlib import Path

import pytest

from cas_async.scenario import ScenarioError, load_scenario
from cas_async.scenario._spec._capacity import (
    ROBOT_MEMORY,
    SAMPLE_MEMORY,
    Capacity,
    capacity_problems,
)

GIB = 1024**3
ROOMY = Capacity(memory=64 * GIB, descriptors=100_000, descriptor_limit=100_000, ports=28_232)


def test_what_fits_is_not_a_problem() -> None:
    counts = {"stations": 4, "transporters.count": 10_000}
    assert capacity_problems(counts, "udp", ROOMY, samples=3600) == []


def test_too_many_for_memory_names_the_key_with_the_most_robots() -> None:
    small = Capacity(memory=GIB)
    [(key, message)] = capacity_problems(
        {"stations.repeat": 4_000, "transporters.count": 10**12}, "memory", small
    )
    assert key == "transporters.count"
    assert message.startswith("1,000,000,000,000 robots (1,000,000,004,000 in all) need about ")
    assert f"at most about {GIB // ROBOT_MEMORY:,} robots" in message


def test_numbers_beyond_a_quadrillion_are_written_short() -> None:
    [(key, message)] = capacity_problems({"count": 10**23}, "memory", Capacity(memory=GIB))
    assert key == "count"
    assert message.startswith("1e+23 robots need about ")
    assert "EiB" in message
    assert len(message) < 200


def test_the_sum_counts_even_when_no_key_alone_is_too_many() -> None:
    half = GIB // ROBOT_MEMORY // 2 + 1
    [(key, _)] = capacity_problems({"a": half, "b": half + 1}, "memory", Capacity(memory=GIB))
    assert key == "b"


def test_udp_needs_a_descriptor_and_a_port_per_robot() -> None:
    tight = Capacity(memory=64 * GIB, descriptors=1_000, descriptor_limit=1_024, ports=500)
    problems = capacity_problems({"robots": 2_000}, "udp", tight)
    assert [key for key, _ in problems] == ["robots", "robots"]
    descriptors, ports = (message for _, message in problems)
    assert "may open 1,000 more files (hard limit 1,024" in descriptors
    assert "hands out 500 (net.ipv4.ip_local_port_range)" in ports
    assert capacity_problems({"robots": 2_000}, "memory", tight) == []  # no sockets in memory


def test_a_trace_larger_than_the_robots_blames_the_trace_interval() -> None:
    capacity = Capacity(memory=GIB)
    samples = GIB // (20 * SAMPLE_MEMORY) + 1
    [(key, message)] = capacity_problems({"robots": 20}, "memory", capacity, samples=samples)
    assert key == "run.trace_interval"
    assert "samples (run.max_time / run.trace_interval) of 20 robots" in message


def test_limits_that_cannot_be_read_are_not_checked() -> None:
    assert capacity_problems({"robots": 10**30}, "udp", Capacity(), samples=1e300) == []


def test_this_machine_reports_what_linux_tells() -> None:
    capacity = Capacity.of_this_machine()
    if Path("/proc/meminfo").exists():
        assert capacity.memory is not None
        assert capacity.memory > 0
    if Path("/proc/sys/net/ipv4/ip_local_port_range").exists():
        assert capacity.ports is not None
        assert capacity.ports > 0


@pytest.mark.parametrize(
    ("override", "key"),
    [
        pytest.param("robots.count=1000000000000", "robots.count", id="1e12"),
        pytest.param("robots.count=99999999999999999999999", "robots.count", id="1e23"),
        pytest.param("run.trace_interval=1e-300", "run.trace_interval", id="trace"),
    ],
)
def test_the_loader_refuses_before_the_app_checks_or_builds(
    tmp_path: Path, override: str, key: str
) -> None:
    path = tmp_path / "big.toml"
    # The fake app's own check refuses more than 100 robots: the size check comes first.
    path.write_text(
        'app = "tests.scenario.fake_app"\n[run]\nvirtual = true\n[world]\nwidth = 1\nheight = 1\n',
        encoding="utf-8",
    )
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path, [override])
    [(found, _)] = caught.value.problems
    assert found == key
