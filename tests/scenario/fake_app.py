"""A tiny application for the scenario loader's tests: robots that are only configured."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import Any

from cas_async.scenario import Mission, ScenarioError, SimulationSetup, setting


@dataclass(frozen=True)
class RobotsConfig:
    count: int = setting(3, ge=1, doc="robots in the swarm")
    speed: float = setting(5.0, gt=0, doc="full speed, distance units per second")


@dataclass(frozen=True)
class FakeConfig:
    robots: RobotsConfig = setting(default_factory=RobotsConfig)
    label: str = "fake"


class FakeApp:
    name = "Fake"
    item_name = "token"
    config_type = FakeConfig

    def robots(self, config: FakeConfig) -> dict[str, int]:
        return {"robots.count": config.robots.count}

    def check(self, config: FakeConfig, world: tuple[float, float]) -> None:
        if config.robots.count > 100:
            raise ScenarioError(
                [("robots.count", f"at most 100 robots, got {config.robots.count}")]
            )

    def build(self, setup: SimulationSetup) -> Mission:
        return Mission(robots=[], target=0)


app = FakeApp()
other = FakeApp()  # reached with "tests.scenario.fake_app:other"

not_an_app = object()


class _NoRobots:
    """The README's contract before it listed ``robots``: everything else is there."""

    name = "No robots"
    config_type = FakeConfig

    def check(self, config: FakeConfig, world: tuple[float, float]) -> None:
        pass

    def build(self, setup: SimulationSetup) -> Mission:
        return Mission(robots=[], target=0)


no_robots = _NoRobots()


class _NotCallable(FakeApp):
    build = "robots go here"  # type: ignore[assignment]
    item_name = 3  # type: ignore[assignment]


not_callable = _NotCallable()


class _WrongCounts(FakeApp):
    def robots(self, config: FakeConfig) -> dict[str, int]:
        return {"robots.count": "three"}  # type: ignore[dict-item]


wrong_counts = _WrongCounts()


class _Untyped:
    name = "Untyped"
    item_name = "thing"
    config_type: Any = dict  # not a dataclass

    def robots(self, config: Any) -> dict[str, int]:
        return {}

    def check(self, config: Any, world: tuple[float, float]) -> None:
        pass

    def build(self, setup: SimulationSetup) -> Mission:
        return Mission(robots=[], target=0)


untyped = _Untyped()


@dataclass(frozen=True)
class _ClashingConfig:
    world: int = 0  # the runner's [world], not the app's
    run: int = 0


class _Clashing(FakeApp):
    config_type = _ClashingConfig  # type: ignore[assignment]


clashing = _Clashing()


class _SlowBuild(FakeApp):
    """Says "building" on stderr, then takes up to a minute to build nothing."""

    def build(self, setup: SimulationSetup) -> Mission:
        print("building", file=sys.stderr, flush=True)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            time.sleep(0.01)
        return Mission(robots=[], target=0)


slow_build = _SlowBuild()
