"""The gathering tutorial app (``examples/gathering``), and the page that teaches it.

Each layer alone (``LayerHarness``), the swarm (``cas_robots`` on virtual time), the
scenario end to end over seeds (``run_scenario_file``), the command line once, and
docs/tutorial.md: every excerpt it shows is in these files.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from collections.abc import Collection, Sequence
from pathlib import Path

import numpy as np
import pytest

from cas_async import ConstantSpeed, MemoryTransport, Message, MsgType, Pose, Robot, VirtualClock
from cas_async.scenario import (
    RunStatus,
    ScenarioError,
    ScenarioRun,
    SimulationSetup,
    load_scenario,
)
from cas_async.sim import Environment, SimulatedMiddleware
from cas_async.testing import LayerHarness, Robots, run_scenario_file, run_until
from examples.gathering.app import GatheringConfig, app
from examples.gathering.drive import Drive
from examples.gathering.messages import MESSAGES, Arrived, DriveTo, Position
from examples.gathering.plan import Plan, Point
from tests.test_docs_pages import excerpt_of

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "gathering"
SCENARIO = EXAMPLE / "gathering.toml"


def arrive(msg: Message) -> Message | None:
    """The Drive layer, scripted: it has arrived wherever it is sent."""
    match msg:
        case DriveTo(x=x, y=y):
            return Arrived(x, y)
    return None


def points(messages: Sequence[Message]) -> list[tuple[str, Point]]:
    """Each message's class name and ``(x, y)``."""
    found: list[tuple[str, Point]] = []
    for msg in messages:
        match msg:
            case Position(x=x, y=y) | DriveTo(x=x, y=y) | Arrived(x=x, y=y):
                found.append((type(msg).__name__, (x, y)))
            case _:
                raise AssertionError(f"not a gathering message: {msg!r}")
    return found


# -- one layer at a time ----------------------------------------------------------------


@pytest.mark.cas_virtual
async def test_plan_drives_to_the_centroid_once_it_heard_everyone() -> None:
    plan = Plan(home=(0.0, 0.0), team=[1, 2, 3], patience=5.0)
    async with LayerHarness(plan, level=0, height=2, peers=[2, 3], messages=MESSAGES) as h:
        h.answer_below(DriveTo, arrive)  # the layer below arrives at once
        await h.settle()
        assert points(h.sent_to(2)) == [("Position", (0.0, 0.0))]  # told everyone
        h.from_peer(2, Position(3.0, 0.0))
        h.from_peer(3, Position(0.0, 3.0))
        await h.settle()
        assert points(h.sent_down) == [("DriveTo", (1.0, 1.0))]
        assert plan.arrived == (1.0, 1.0)


@pytest.mark.cas_virtual
async def test_plan_meets_with_those_it_heard_once_its_patience_runs_out() -> None:
    plan = Plan(home=(0.0, 0.0), team=[1, 2, 3], patience=2.0)
    async with LayerHarness(plan, level=0, height=2, peers=[2, 3], messages=MESSAGES) as h:
        h.answer_below(DriveTo, arrive)
        h.from_peer(2, Position(4.0, 2.0))  # robot 3 says nothing
        await h.settle()
        assert h.sent_down == []
        await run_until(lambda: h.sent_down, timeout=3.0)
        assert plan.clock.now() == pytest.approx(2.0, abs=0.02)
        assert points(h.sent_down) == [("DriveTo", (2.0, 1.0))]


@pytest.mark.cas_virtual
async def test_drive_answers_drive_to_once_the_robot_is_there() -> None:
    environment, clock = Environment(), VirtualClock()
    environment.add_robot(1, Pose(0.0, 0.0, 0.0))
    middleware = SimulatedMiddleware(
        environment, 1, clock, turn_rate=math.inf, speed_profile=ConstantSpeed(2.0)
    )
    async with LayerHarness(
        Drive(middleware), level=1, height=2, messages=MESSAGES, clock=clock
    ) as h:
        # A request from above: Drive's get_intra_msg_reply answers it.
        h.from_above(DriveTo(3.0, 4.0, msg_type=MsgType.NEGOTIATION))
        await run_until(lambda: h.sent_up, timeout=10.0)
        assert points(h.sent_up) == [("Arrived", (3.0, 4.0))]
        assert clock.now() == 2.5  # 5 m at 2 m/s
        assert environment.pose_at(1, clock.now()).x == 3.0


# -- the swarm ---------------------------------------------------------------------------


@pytest.mark.cas_virtual
async def test_the_swarm_meets_at_the_centroid_of_where_it_started(
    cas_robots: Robots, cas_memory: MemoryTransport
) -> None:
    environment, clock = Environment(), VirtualClock()
    setup = SimulationSetup(
        GatheringConfig(), (10.0, 10.0), environment, clock, cas_memory, np.random.default_rng(5)
    )
    mission = app.build(setup)  # the app's own robots, outside any scenario
    start = environment.positions_at(0.0).xy
    swarm = await cas_robots.swarm(mission.robots)
    await swarm.run()  # until every robot's Plan has arrived
    end = environment.positions_at(clock.now()).xy
    assert len({(x, y) for x, y in end.tolist()}) == 1  # the very same point for all
    assert np.allclose(end[0], start.mean(axis=0))


def robot(
    robot_id: int,
    home: Point,
    team: Collection[int],
    world: tuple[Environment, VirtualClock, MemoryTransport],
) -> Robot:
    environment, clock, transport = world
    environment.add_robot(robot_id, Pose(*home, 0.0))
    middleware = SimulatedMiddleware(
        environment, robot_id, clock, turn_rate=math.inf, speed_profile=ConstantSpeed(1.0)
    )
    layers = [Plan(home, team, patience=3.0), Drive(middleware)]
    return Robot(robot_id, layers, transport=transport, clock=clock, messages=MESSAGES)


@pytest.mark.cas_virtual
async def test_a_robot_that_never_shows_up_is_waited_for_then_left_out(
    cas_robots: Robots, cas_memory: MemoryTransport
) -> None:
    world = Environment(), VirtualClock(), cas_memory
    team = (1, 2, 3)  # robot 3 never starts
    swarm = await cas_robots.swarm(
        [robot(1, (0.0, 0.0), team, world), robot(2, (4.0, 0.0), team, world)]
    )
    await swarm.run()
    environment, clock, _ = world
    assert clock.now() == 5.0  # 3 s of patience, then 2 m at 1 m/s
    assert environment.positions_at(clock.now()).as_dict() == {1: (2.0, 0.0), 2: (2.0, 0.0)}


# -- the scenario ------------------------------------------------------------------------


@pytest.mark.parametrize(
    "overrides",
    [("run.seed=1",), ("run.seed=2",), ("run.seed=3", "robots.count=40")],
    ids=["seed1", "seed2", "forty-robots"],
)
def test_the_scenario_gathers_every_robot(overrides: tuple[str, ...]) -> None:
    outcome = run_scenario_file(SCENARIO, *overrides)
    result = outcome.result
    assert result.status is RunStatus.COMPLETED, result.error
    assert result.delivered == result.target == len(outcome.environment)
    assert result.makespan == max(result.delivery_times) == result.sim_time
    assert result.samples["arrival_time"] == result.delivery_times
    meeting = (float(result.extra["meeting_x"]), float(result.extra["meeting_y"]))
    final = outcome.environment.positions_at(result.sim_time).as_dict()
    assert all(math.dist(at, meeting) <= 0.5 for at in final.values())
    assert result.messages_external == {"Position": len(final) * (len(final) - 1)}


def test_a_spawn_area_outside_the_world_is_refused_naming_its_key() -> None:
    with pytest.raises(ScenarioError) as caught:
        load_scenario(SCENARIO, ["robots.spawn=[[0.0, 0.0], [30.0, 5.0]]"])
    assert [key for key, _ in caught.value.problems] == ["robots.spawn"]
    assert "inside the world (0..20, 0..20)" in str(caught.value)


class PatientPlan(Plan):
    """A replacement for the plan level (``[layers] plan``): twice as patient."""

    def __init__(self, home: Point, team: Collection[int], patience: float) -> None:
        super().__init__(home, team, patience * 2)


def test_a_scenario_replaces_the_plan_level_by_name() -> None:
    scenario = load_scenario(
        SCENARIO,
        [
            "run.virtual=true",
            'run.transport="memory"',
            "layers.plan=tests.test_tutorial:PatientPlan",
        ],
    )
    run = ScenarioRun(scenario)  # builds the robots: no loop needed yet
    plans = [robot.layers[0] for robot in run.swarm]
    assert {type(plan) for plan in plans} == {PatientPlan}
    assert all(isinstance(plan, Plan) and plan.patience == 4.0 for plan in plans)


def test_the_command_line_runs_the_scenario(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "cas_async", "run", "examples/gathering/gathering.toml",
         "--no-plots", "--out", str(tmp_path)],
        cwd=ROOT, capture_output=True, text=True, timeout=60, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert re.search(r"^robots gathered +5 of 5$", done.stdout, re.M), done.stdout
    (shown,) = _tutorial_blocks("console")  # the output the page shows
    for line in shown.splitlines()[1:]:
        if "..." not in line and not line.startswith("wrote "):  # written to tmp_path here
            assert line in done.stdout
    results = json.loads((tmp_path / "results.json").read_text())
    assert (results["kind"], results["status"], results["delivered"]) == (
        "gathering",
        "completed",
        5,
    )


# -- the tutorial's page -----------------------------------------------------------------


def _tutorial_blocks(language: str) -> list[str]:
    page = (ROOT / "docs" / "tutorial.md").read_text(encoding="utf-8")
    return re.findall(rf"^```{language}\b[^\n]*\n(.*?)^```", page, re.S | re.M)


@pytest.mark.parametrize("language", ["python", "toml"])
def test_every_excerpt_of_the_tutorial_is_in_the_example_or_its_tests(language: str) -> None:
    """Each block, modulo whitespace at its ends, is in one file; ``...`` lines elide, in order."""
    sources = [path.read_text() for path in sorted(EXAMPLE.glob("*.py"))]
    sources += [Path(__file__).read_text(), SCENARIO.read_text()]
    blocks = _tutorial_blocks(language)
    assert blocks, f"the tutorial shows no {language} block"
    stale = [block for block in blocks if not any(excerpt_of(block, text) for text in sources)]
    assert stale == [], "excerpts not found verbatim in examples/gathering or this file"
