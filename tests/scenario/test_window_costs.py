"""What a run across processes spent on its windows, from what its workers report."""

from __future__ import annotations

import math

import msgspec
import pytest

from cas_async.scenario._processes._control import Counts, Remote, Window
from cas_async.scenario._processes._observer import Observation
from cas_async.scenario._processes._window_costs import WindowCosts


def window(k: int, busy: float, effects: int = 0) -> Window:
    remote = [Remote(0.1, 1, 2, n, 3) for n in range(effects)]
    return Window(k, 0.0, Observation(), remote, Counts(), busy=busy)


def test_the_busiest_worker_against_the_average_one_is_the_imbalance() -> None:
    costs = WindowCosts()
    costs.window(0, window(0, 1.0, effects=2))
    costs.window(1, window(0, 3.0))
    costs.window(0, window(1, 2.0))
    costs.window(0, window(2, 2.0, effects=1))
    costs.observed(0.5)
    costs.observed(0.25)
    costs.waited(0, 4.0, 1.0)
    costs.waited(1, 6.0, 0.5)
    assert costs.stats(2, virtual=True) == {
        "workers": 2,
        "windows": 3,  # the most a worker closed: each runs its own
        "cross_process_effects": 3,
        "worker_waited_s": 6.0,
        "worker_waited_grant_s": 1.0,
        "world_observing_s": 0.75,
        "window_busy_mean_s": 4.0,  # (1 + 2 + 2 + 3) / 2
        "window_busy_max_s": 5.0,  # worker 0: 1 + 2 + 2
    }


def test_scaled_time_counts_the_effects_as_they_flow() -> None:
    costs = WindowCosts()
    costs.flowed(window(-1, 0.0, effects=2))
    costs.flowed(window(-1, 0.0, effects=1))
    assert costs.stats(3, virtual=False) == {"workers": 3, "cross_process_effects": 3}


@pytest.mark.parametrize("busy", [0.0, 0.125])
def test_a_window_carries_how_long_its_worker_was_busy(busy: float) -> None:
    sent = window(4, busy)
    assert msgspec.msgpack.decode(msgspec.msgpack.encode(sent), type=Window) == sent


@pytest.mark.parametrize("busy", [-1.0, math.nan, math.inf])
def test_a_window_whose_busy_time_is_negative_or_not_finite_does_not_decode(busy: float) -> None:
    # What the world sums must stay a number: a forged or broken window is refused.
    with pytest.raises(msgspec.ValidationError, match="busy"):
        msgspec.msgpack.decode(msgspec.msgpack.encode(window(4, busy)), type=Window)
