"""Apps refused at start-up, for the command line's tests (``tests/test_cli_startup.py``)."""

from __future__ import annotations

from dataclasses import dataclass

from cas_async import ConfigurationError, Layer, Pose, Robot, VirtualClock
from cas_async.scenario import Mission, SimulationSetup, setting


@dataclass(frozen=True)
class Robots:
    count: int = setting(2, ge=1, doc="robots")


@dataclass(frozen=True)
class Config:
    robots: Robots = setting(default_factory=Robots)


class _App:
    name = "Refused"
    config_type = Config

    def robots(self, config: Config) -> dict[str, int]:
        return {"robots.count": config.robots.count}

    def check(self, config: Config, world: tuple[float, float]) -> None:
        pass

    def build(self, setup: SimulationSetup[Config]) -> Mission:
        raise NotImplementedError


class _RefusesToBuild(_App):
    def build(self, setup: SimulationSetup[Config]) -> Mission:
        raise ConfigurationError("robots.count: this app builds at most 1 robot on Tuesdays")


class _OwnClock(_App):
    """Builds its robots on a clock of its own: a virtual one, which a scaled run cannot start."""

    def build(self, setup: SimulationSetup[Config]) -> Mission:
        robots = []
        for robot_id in range(1, setup.config.robots.count + 1):
            setup.environment.add_robot(robot_id, Pose(1.0, 1.0, 0.0))
            robots.append(
                Robot(robot_id, [Layer()], transport=setup.transport, clock=VirtualClock())
            )
        return Mission(robots, target=1)


refuses_to_build = _RefusesToBuild()
own_clock = _OwnClock()
