"""The garbage collector's youngest generation is sized to the swarm during a run, then restored."""

from __future__ import annotations

import gc
from collections.abc import Iterator

import pytest

from cas_async.scenario._gc_policy import CEILING, PER_ROBOT, young_generation_for


@pytest.fixture(autouse=True)
def thresholds() -> Iterator[tuple[int, int, int]]:
    """Every test starts from CPython's defaults and leaves the process as it found it."""
    before = gc.get_threshold()
    enabled = gc.isenabled()
    gc.set_threshold(700, 10, 10)
    gc.enable()
    yield gc.get_threshold()
    gc.set_threshold(*before)
    if not enabled:
        gc.disable()


@pytest.mark.parametrize(
    ("robots", "expected"),
    [
        pytest.param(1, 700, id="never-below-the-default"),
        pytest.param(25, 1000, id="thesis"),
        pytest.param(290, 290 * PER_ROBOT, id="hundreds"),
        pytest.param(11_600, 11_600 * PER_ROBOT, id="ten-thousand"),
        pytest.param(30_000, CEILING, id="capped"),
    ],
)
def test_the_young_generation_grows_with_the_swarm(robots: int, expected: int) -> None:
    with young_generation_for(robots) as used:
        assert used == expected
        assert gc.get_threshold() == (expected, 10, 10)
    assert gc.get_threshold() == (700, 10, 10)


def test_the_threshold_is_restored_when_the_run_raises() -> None:
    with pytest.raises(RuntimeError, match="boom"), young_generation_for(1000):
        raise RuntimeError("boom")
    assert gc.get_threshold() == (700, 10, 10)


def test_a_threshold_changed_during_the_run_is_left_alone() -> None:
    with young_generation_for(1000):
        gc.set_threshold(5000, 20, 30)
    assert gc.get_threshold() == (5000, 20, 30)


def test_a_disabled_collector_is_not_touched() -> None:
    gc.disable()
    with young_generation_for(1000) as used:
        assert used == 700
        assert gc.get_threshold() == (700, 10, 10)
    assert not gc.isenabled()
