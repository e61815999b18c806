"""A process builds only the robots it runs (``SimulationSetup.holds``), placing every robot alike.

Across processes each worker runs a share of the robots and the world none: an app
that asks ``setup.holds(robot_id)`` builds the layers and robots of its share only,
but adds every robot to the Environment and draws every random number, so that every
process places every robot where the others do.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from cas_async import MemoryTransport
from cas_async.scenario import Mission, SimulationSetup, load_scenario
from cas_async.sim import Environment

ROOT = Path(__file__).resolve().parents[2]
SCALE_25 = ROOT / "apps" / "fire_brigade" / "scenarios" / "scale_25.toml"
GATHERING = ROOT / "examples" / "gathering" / "gathering.toml"


def build(
    path: Path, share: frozenset[int] | None
) -> tuple[SimulationSetup[Any], Mission, Environment]:
    scenario = load_scenario(path)
    clock = scenario.clock()
    environment = scenario.environment(clock)
    transport = MemoryTransport()
    setup = scenario.setup(environment, clock, transport, share)
    return setup, scenario.app.build(setup), environment


def test_in_one_process_every_robot_is_held_and_built() -> None:
    setup, mission, environment = build(SCALE_25, None)
    assert all(setup.holds(robot) for robot in environment.robot_ids)
    assert [robot.robot_id for robot in mission.robots] == list(environment.robot_ids)


def test_a_share_builds_its_robots_only_and_places_every_robot_alike() -> None:
    _, everyone, whole = build(SCALE_25, None)
    share = frozenset({1, 5, 20, 28})
    setup, mission, environment = build(SCALE_25, share)
    assert not setup.holds(2)
    assert sorted(robot.robot_id for robot in mission.robots) == sorted(share)
    assert environment.robot_ids == whole.robot_ids  # every robot has its place
    assert np.array_equal(environment.positions_at(0.0).xy, whole.positions_at(0.0).xy)
    assert mission.groups == everyone.groups  # and its group
    # Each built robot is the one the whole build makes (its seed drawn in turn).
    built = {robot.robot_id: robot for robot in everyone.robots}
    for robot in mission.robots:
        assert len(robot.layers) == len(built[robot.robot_id].layers)


def test_the_world_builds_no_robot() -> None:
    for path in (SCALE_25, GATHERING):
        _, mission, environment = build(path, frozenset())
        assert mission.robots == []
        assert len(environment.robot_ids) > 0
