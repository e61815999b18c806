"""The garbage collector's youngest generation is sized to the swarm during a run, then restored."""

from __future__ import annotations

import gc
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

import cas_async
from apps.fire_brigade.app import FireBrigade
from cas_async._core._gc_policy import CEILING, PER_ROBOT, while_building, young_generation_for
from cas_async.scenario import ScenarioRun, load_scenario
from cas_async.scenario._processes import _worker as worker_module
from cas_async.scenario._processes._control import Welcome
from cas_async.scenario._processes._world import World
from cas_async.scenario._run import _runner as runner_module

SHIPPED = Path(__file__).resolve().parents[2] / "apps/fire_brigade/scenarios/thesis_5_8_1.toml"


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


@pytest.mark.parametrize("virtual", [False, True], ids=["scaled", "virtual"])
def test_a_worker_sizes_the_young_generation_to_its_share_of_the_robots(
    monkeypatch: pytest.MonkeyPatch, virtual: bool
) -> None:
    # A worker builds and runs its share of the robots (an app that asks holds());
    # with CPython's default threshold a worker of scale_2500 holding every robot
    # took 47 CPU seconds against 38. The world and the run itself are stood in for: what is
    # checked is the threshold in force while the worker runs.
    virtual_time = ["run.virtual=true", 'run.transport="memory"'] if virtual else []
    scenario = load_scenario(SHIPPED, virtual_time)
    shares = [list(range(1, 101)), list(range(101, 151))]
    welcome = Welcome(0, "run", str(scenario.path), scenario.data, shares)
    seen: list[int] = []

    async def join(*_: object) -> Welcome:
        return welcome

    class Running:
        def __init__(self, *args: object) -> None:
            pass

        async def run(self) -> int:
            seen.append(gc.get_threshold()[0])
            return 0

    monkeypatch.setattr(worker_module, "join", join)
    monkeypatch.setattr(worker_module, "_Worker", Running)
    assert worker_module.run_worker("tcp/127.0.0.1:7447", None, quiet=True) == 0
    assert seen == [100 * PER_ROBOT]  # worker 0's share: it builds no other (holds())
    assert gc.get_threshold() == (700, 10, 10)


def test_while_building_the_young_generation_is_at_its_ceiling() -> None:
    with while_building() as used:
        assert used == CEILING
        assert gc.get_threshold() == (CEILING, 10, 10)
    assert gc.get_threshold() == (700, 10, 10)


def test_a_run_builds_its_mission_with_the_young_generation_at_its_ceiling(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # What a build allocates lives as long as the run: building scale_10000 with
    # CPython's default threshold took 4.0 s, 1.8 s of it in full collections.
    built = FireBrigade.build
    seen: list[int] = []

    def build(app: FireBrigade, setup: Any) -> Any:
        seen.append(gc.get_threshold()[0])
        return built(app, setup)

    monkeypatch.setattr(FireBrigade, "build", build)
    ScenarioRun(load_scenario(SHIPPED))
    assert seen == [CEILING]
    assert gc.get_threshold() == (700, 10, 10)


class _Sized(Exception):
    """Raised by the stand-in for young_generation_for once it was called: the run stops there."""


def test_a_world_sizes_the_young_generation_to_the_robots_it_observes(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # A world runs no robot but observes them all in its mirror: with CPython's
    # default threshold its full collections stalled the workers' grants.
    pytest.importorskip("zenoh")  # a World needs it importable; nothing is started here
    scenario = load_scenario(SHIPPED, ["run.virtual=true", 'run.transport="memory"'])
    sized: list[int] = []

    def young_generation(robots: int) -> object:
        sized.append(robots)
        raise _Sized

    monkeypatch.setattr(runner_module, "young_generation_for", young_generation)

    async def enter() -> None:
        run = ScenarioRun(scenario, world=World(scenario, workers=2, key=None, spawn=False))
        assert len(run.swarm) == 0
        with pytest.raises(_Sized):
            await run.__aenter__()

    cas_async.run(enter(), virtual=True)
    assert sized == [20]  # thesis 5.8.1: 20 robots, all in the workers
