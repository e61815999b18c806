"""A scenario's ``[layers]``: any level of the app's stack, replaced by a class path."""

from __future__ import annotations

import io
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from apps.fire_brigade import SoloStrategy
from apps.fire_brigade import app as fire_brigade
from apps.fire_brigade.task import Task
from cas_async import (
    ConfigurationError,
    Layer,
    MemoryTransport,
    Message,
    Robot,
    VirtualClock,
    message,
)
from cas_async.scenario import LayerSlot, Scenario, ScenarioError, ScenarioRun, load_scenario
from cas_async.scenario._spec._layers import layer_classes
from cas_async.scenario._spec._loader import scenario_from_data
from cas_async.sim import Environment
from cas_async.testing import run_scenario_file
from tests.scenario.swaps import CountingTask, SoloByLayers

THESIS = Path(__file__).resolve().parents[2] / "apps/fire_brigade/scenarios/thesis_5_8_1.toml"
SWAPS = "tests.scenario.swaps"
LEVELS = "goal (0), strategy (1), group_activity (2), task (3), action (4)"

WriteScenario = Callable[[str], Path]


@pytest.fixture
def write(tmp_path: Path) -> WriteScenario:
    """Factory: ``write(layers)`` makes a Fire Brigade scenario (§5.8.1) with these lines."""

    def make(text: str) -> Path:
        path = tmp_path / "swapped.toml"
        path.write_text(f'extends = "{THESIS.as_posix()}"\n{text}', encoding="utf-8")
        return path

    return make


def problems_loading(path: Path, overrides: tuple[str, ...] = ()) -> list[tuple[str, str]]:
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path, overrides)
    assert caught.value.file == str(path)
    assert str(caught.value).startswith(f"{path}: ")
    return list(caught.value.problems)


def built_robots(scenario: Scenario) -> list[Robot]:
    setup = scenario.setup(Environment(), VirtualClock(), MemoryTransport())
    return list(scenario.app.build(setup).robots)


# -- what is refused ---------------------------------------------------------------------------

REFUSED = [
    pytest.param(
        'layers = "task"',
        "layers",
        'expected a table of level = class path, got "task"',
        id="not-a-table",
    ),
    pytest.param(
        f'[layers]\ntusk = "{SWAPS}.CountingTask"',
        "layers.tusk",
        f"no level named 'tusk' (did you mean 'task'? the levels are {LEVELS})",
        id="unknown-name",
    ),
    pytest.param(
        f'[layers]\n5 = "{SWAPS}.CountingTask"',
        "layers.5",
        f"no level 5: the stack has 5 levels, 0 to 4 ({LEVELS})",
        id="index-too-high",
    ),
    pytest.param(
        f'[layers]\n-1 = "{SWAPS}.CountingTask"',
        "layers.-1",
        "no level -1: the stack has 5 levels, 0 to 4",
        id="index-negative",
    ),
    pytest.param(
        f'[layers]\ntask = "{SWAPS}.CountingTask"\n3 = "{SWAPS}:CountingTask"',
        "layers.3",
        "names level task (3) again: layers.task already replaces it",
        id="same-level-twice",
    ),
    pytest.param(
        "[layers]\ntask = 3",
        "layers.task",
        'expected a class path such as "package.module.Class" or "package.module:Class", got 3',
        id="not-a-string",
    ),
    pytest.param(
        '[layers]\ntask = "CountingTask"',
        "layers.task",
        'expected a class path such as "package.module.Class" or "package.module:Class", '
        'got "CountingTask"',
        id="no-module",
    ),
    pytest.param(
        '[layers]\ntask = "tests.scenario.swaps/CountingTask"',
        "layers.task",
        "expected a class path",
        id="not-a-path",
    ),
    pytest.param(
        '[layers]\ntask = "tests.scenario.no_such_module.Task"',
        "layers.task",
        "cannot import 'tests.scenario.no_such_module': "
        "No module named 'tests.scenario.no_such_module'",
        id="module-not-found",
    ),
    pytest.param(
        f'[layers]\ntask = "{SWAPS}.NoSuchTask"',
        "layers.task",
        "module 'tests.scenario.swaps' has no attribute 'NoSuchTask'",
        id="no-such-attribute",
    ),
    pytest.param(
        f'[layers]\ntask = "{SWAPS}:make_task"',
        "layers.task",
        "expected a class, got 'tests.scenario.swaps:make_task', a function",
        id="not-a-class",
    ),
    pytest.param(
        f'[layers]\ntask = "{SWAPS}.NotALayer"',
        "layers.task",
        f"{SWAPS}.NotALayer is not a layer: it does not subclass cas_async.Layer",
        id="not-a-layer",
    ),
    pytest.param(
        f'[layers]\ntask = "{SWAPS}.PlainLayer"',
        "layers.task",
        f"{SWAPS}.PlainLayer does not subclass apps.fire_brigade.base.BrigadeLayer: "
        "the task level is built as BrigadeLayer is built (same constructor, same role)",
        id="not-the-slot-base",
    ),
    pytest.param(
        f'[layers]\nstrategy = "{SWAPS}.CountingTask"',
        "layers.strategy",
        f"{SWAPS}.CountingTask does not subclass apps.fire_brigade.strategy.Strategy: "
        "the strategy level is built as Strategy is built",
        id="another-levels-class",
    ),
    pytest.param(
        f'[layers]\ntask = "{SWAPS}.AbstractTask"',
        "layers.task",
        f"{SWAPS}.AbstractTask is abstract (it lacks patience): it cannot be built",
        id="abstract",
    ),
    pytest.param(
        f'[layers]\ntask = "{SWAPS}.DeafTask"',
        "layers.task",
        f"{SWAPS}.DeafTask.handle_msg(self) -> None cannot be called as "
        "Layer's async def handle_msg(self, msg: Message) -> None",
        id="hook-signature",
    ),
    pytest.param(
        '[layers]\ntask = "tests.scenario.swaps_messages.LoudTask"',
        "layers.task",
        "tests.scenario.swaps_messages.LoudTask would change the stack's message set: "
        "it brings tests.scenario.swaps_messages.SwapShout "
        "(defined in tests.scenario.swaps_messages), not among the app's messages",
        id="module-defines-a-message",
    ),
    pytest.param(
        f'[layers]\ntask = "{SWAPS}.ChattyTask"',
        "layers.task",
        f"{SWAPS}.ChattyTask would change the stack's message set: it brings "
        "tests.scenario.swaps_messages.SwapShout (used by ChattyTask.inner_process)",
        id="method-uses-a-message",
    ),
]


@pytest.mark.parametrize(("text", "key", "reason"), REFUSED)
def test_refuses(write: WriteScenario, text: str, key: str, reason: str) -> None:
    problems = problems_loading(write(text))
    assert len(problems) == 1, problems
    assert problems[0][0] == key
    assert reason in problems[0][1]


@pytest.mark.parametrize(
    ("app", "reason"),
    [
        pytest.param(
            "tests.scenario.fake_app",
            "Fake's levels cannot be replaced: the app declares no stack",
            id="no-stack",
        ),
        pytest.param(
            f"{SWAPS}:silent",
            "Fire Brigade declares a stack but no messages",
            id="no-messages",
        ),
    ],
)
def test_refuses_an_app_that_does_not_name_its_levels(
    tmp_path: Path, app: str, reason: str
) -> None:
    path = tmp_path / "scenario.toml"
    extends = "" if app == "tests.scenario.fake_app" else f'extends = "{THESIS.as_posix()}"\n'
    path.write_text(
        f'{extends}app = "{app}"\n[world]\nwidth = 10\nheight = 10\n'
        f'[layers]\ntask = "{SWAPS}.CountingTask"\n',
        encoding="utf-8",
    )
    [(key, problem)] = problems_loading(path)
    assert key == "layers"
    assert reason in problem


def test_an_app_without_a_stack_takes_an_empty_table(tmp_path: Path) -> None:
    path = tmp_path / "scenario.toml"
    path.write_text(
        'app = "tests.scenario.fake_app"\n[world]\nwidth = 10\nheight = 10\n[layers]\n',
        encoding="utf-8",
    )
    assert load_scenario(path).layers == {}


def test_reports_every_problem_at_once(write: WriteScenario) -> None:
    path = write(
        f'[run]\nseed = -1\n[layers]\ntusk = "{SWAPS}.CountingTask"\n'
        f'strategy = "{SWAPS}.NotALayer"\naction = 7\n'
    )
    keys = [key for key, _ in problems_loading(path)]
    assert keys == ["run.seed", "layers.tusk", "layers.strategy", "layers.action"]


def test_an_override_is_checked_as_the_file_is(write: WriteScenario) -> None:
    problems = problems_loading(write(""), (f"layers.9={SWAPS}.CountingTask",))
    assert problems == [("layers.9", f"no level 9: the stack has 5 levels, 0 to 4 ({LEVELS})")]


def test_the_command_line_refuses_a_hook_it_could_not_call_with_exit_2(
    write: WriteScenario,
) -> None:
    from cas_async._cli._main import main

    path = write(f'[layers]\ntask = "{SWAPS}.DeafTask"')
    stdout, stderr = io.StringIO(), io.StringIO()
    assert main(["run", str(path), "--no-plots"], stdout=stdout, stderr=stderr) == 2
    assert stderr.getvalue() == (
        f"error: {path}: layers.task: {SWAPS}.DeafTask.handle_msg(self) -> None cannot be "
        "called as Layer's async def handle_msg(self, msg: Message) -> None\n"
    )
    assert stdout.getvalue() == ""  # nothing ran


def test_a_module_that_raises_on_import_says_why(tmp_path: Path) -> None:
    broken = tmp_path / "swap_broken_pkg"
    broken.mkdir()
    (broken / "__init__.py").write_text('raise RuntimeError("half written")\n', encoding="utf-8")
    path = tmp_path / "scenario.toml"
    path.write_text(
        f'extends = "{THESIS.as_posix()}"\n[layers]\ntask = "swap_broken_pkg.Task"\n',
        encoding="utf-8",
    )
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(sys, "path", list(sys.path))  # the loader adds tmp_path to it
        assert problems_loading(path) == [
            (
                "layers.task",
                "cannot import 'swap_broken_pkg': it raised RuntimeError: half written",
            )
        ]


# -- what is put in place ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "overrides"),
    [
        pytest.param(f'[layers]\ntask = "{SWAPS}.CountingTask"', (), id="by-name"),
        pytest.param(f'[layers]\n3 = "{SWAPS}:CountingTask"', (), id="by-index"),
        pytest.param("", (f"layers.task={SWAPS}.CountingTask",), id="set-by-name"),
        pytest.param("", (f"layers.3={SWAPS}:CountingTask",), id="set-by-index"),
    ],
)
def test_builds_the_replacement_at_its_level(
    write: WriteScenario, text: str, overrides: tuple[str, ...]
) -> None:
    scenario = load_scenario(write(text), overrides)
    assert scenario.layers == {"task": CountingTask}
    robots = built_robots(scenario)
    assert robots
    for robot in robots:
        assert isinstance(robot.layers[3], CountingTask)
        assert type(robot.layers[2]).__name__ == "GroupActivity"  # the others are the app's
        assert type(robot.layers[4]).__name__ == "Action"


def test_the_class_path_stays_in_the_data_for_a_worker(write: WriteScenario) -> None:
    scenario = load_scenario(write(""), (f"layers.task={SWAPS}.CountingTask",))
    assert scenario.data["layers"] == {"task": f"{SWAPS}.CountingTask"}
    assert scenario_from_data(scenario.path, scenario.data).layers == {"task": CountingTask}


def test_layers_strategy_wins_over_strategy_name(write: WriteScenario) -> None:
    # The §5.8.1 file names strategy "time_gain"; [layers] puts the solo rule instead.
    scenario = load_scenario(write(f'[layers]\nstrategy = "{SWAPS}.SoloByLayers"'))
    assert scenario.config.strategy.name == "time_gain"
    for robot in built_robots(scenario):
        assert type(robot.layers[1]) is SoloByLayers


def test_strategy_name_still_chooses_without_layers(write: WriteScenario) -> None:
    scenario = load_scenario(write(""), ("strategy.name=solo",))
    assert scenario.layers == {}
    assert {type(robot.layers[1]) for robot in built_robots(scenario)} == {SoloStrategy}


def test_a_users_package_next_to_the_scenario_is_found(tmp_path: Path) -> None:
    package = tmp_path / "swap_user_layers"
    package.mkdir()
    (package / "__init__.py").write_text(
        "from apps.fire_brigade.task import Task\n\nclass MyTask(Task):\n    pass\n",
        encoding="utf-8",
    )
    folder = tmp_path / "scenarios"
    folder.mkdir()
    path = folder / "mine.toml"
    path.write_text(
        f'extends = "{THESIS.as_posix()}"\n[layers]\ntask = "swap_user_layers:MyTask"\n',
        encoding="utf-8",
    )
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(sys, "path", list(sys.path))
        chosen = load_scenario(path).layers["task"]
    assert chosen.__module__ == "swap_user_layers"
    assert issubclass(chosen, Task)


@pytest.mark.parametrize("slot", fire_brigade.stack, ids=lambda slot: slot.name)
def test_the_fire_brigades_own_classes_pass_the_checks(slot: LayerSlot[Any]) -> None:
    problems: list[tuple[str, str]] = []
    table = {slot.name: f"{slot.default.__module__}:{slot.default.__qualname__}"}
    assert layer_classes(table, fire_brigade, problems) == {slot.name: slot.default}
    assert problems == []


# -- runs --------------------------------------------------------------------------------------


def test_a_swapped_run_completes() -> None:
    before = CountingTask.built
    outcome = run_scenario_file(
        THESIS, f"layers.task={SWAPS}.CountingTask", f"layers.strategy={SWAPS}:SoloByLayers"
    )
    result = outcome.result
    assert result.status.name == "COMPLETED", result.error
    assert result.delivered >= 20
    assert CountingTask.built - before == 20  # one Task per robot
    assert result.extra["strategy"] == f"{SWAPS}:SoloByLayers"


def test_naming_the_apps_own_classes_changes_nothing(write: WriteScenario) -> None:
    plain = run_scenario_file(THESIS).result
    named = run_scenario_file(
        write(
            "[layers]\n"
            'strategy = "apps.fire_brigade.strategies.TimeGainStrategy"\n'
            '3 = "apps.fire_brigade.task:Task"\n'
        )
    ).result
    assert named.extra == plain.extra  # the same windows too
    assert plain.extra["strategy"] == "time_gain"
    assert named.delivery_times == plain.delivery_times
    assert named.metrics == plain.metrics


# -- the message check, on its own -------------------------------------------------------------


@message
class SwapPoint(Message):
    x: float = 0.0


@message
class SwapRoute(Message):
    points: tuple[SwapPoint, ...] = ()


class RouteLayer(Layer):
    async def inner_process(self) -> None:
        self.log.debug("%r", SwapRoute(points=(SwapPoint(x=1.0),)))


class _RouteApp:
    name = "Route"
    stack = (LayerSlot("route", Layer, RouteLayer),)

    def __init__(self, *messages: type[Message]) -> None:
        self.messages = messages


def test_messages_nested_in_the_stacks_count_as_its_own() -> None:
    problems: list[tuple[str, str]] = []
    path = f"{__name__}:RouteLayer"
    assert layer_classes({"0": path}, _RouteApp(SwapRoute), problems) == {"route": RouteLayer}
    assert problems == []
    assert layer_classes({"0": path}, _RouteApp(SwapPoint), problems) == {}
    assert problems == [
        (
            "layers.0",
            f"{path} would change the stack's message set: it brings {__name__}.SwapRoute "
            f"(defined in {__name__}), not among the app's messages "
            "(a replacement may use only those)",
        )
    ]


def test_an_app_that_ignores_the_replacement_is_refused_before_the_start(
    write: WriteScenario,
) -> None:
    path = write(f'app = "{SWAPS}:stubborn"\n[layers]\ntask = "{SWAPS}.CountingTask"')
    scenario = load_scenario(path, ["run.virtual=true", "run.transport=memory"])
    with pytest.raises(ConfigurationError) as caught:
        ScenarioRun(scenario)
    assert str(caught.value) == (
        f"{path}: layers.task: robot 1's level 3 was built as Task, not CountingTask: "
        "the app must build each level with setup.layer(SLOT)"
    )
