"""An app whose robotic layer never answers its GoTo requests: the finding of issue 30."""

from __future__ import annotations

from dataclasses import dataclass

from cas_async import Pose
from cas_async.scenario import Mission, SimulationSetup, setting
from tests.test_unanswered_requests import MESSAGES, Asker, Silent


@dataclass(frozen=True)
class Robots:
    count: int = setting(3, ge=1, doc="robots")


@dataclass(frozen=True)
class Config:
    robots: Robots = setting(default_factory=Robots)


class UnansweredApp:
    name = "Unanswered"
    config_type = Config

    def robots(self, config: Config) -> dict[str, int]:
        return {"robots.count": config.robots.count}

    def check(self, config: Config, world: tuple[float, float]) -> None:
        pass

    def build(self, setup: SimulationSetup[Config]) -> Mission:
        robots = []
        for robot_id in range(1, setup.config.robots.count + 1):
            setup.environment.add_robot(robot_id, Pose(float(robot_id), 1.0, 0.0))
            robots.append(setup.robot(robot_id, [Asker(count=2), Silent()], messages=MESSAGES))
        return Mission(robots, target=1)


app = UnansweredApp()
