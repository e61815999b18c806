"""Scenario files end to end: read, override, import the app, validate, check."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from cas_async.scenario import (
    RunConfig,
    Scenario,
    ScenarioError,
    WorldConfig,
    apply_overrides,
    load_scenario,
    parse_override,
)
from tests.scenario import fake_app
from tests.scenario.fake_app import FakeConfig, RobotsConfig

VALID = """
app = "tests.scenario.fake_app"

[run]
seed = 7
virtual = true
transport = "memory"

[world]
width = 200
height = 100.5

[robots]
count = 40
speed = 2.5
"""

MINIMAL = """
app = "tests.scenario.fake_app"
[world]
width = 10
height = 10
"""

WriteScenario = Callable[[str], Path]


@pytest.fixture
def write(tmp_path: Path) -> WriteScenario:
    """Factory: ``path = write(toml_text)`` makes a scenario file under tmp_path."""

    def make(text: str) -> Path:
        path = tmp_path / "scenario.toml"
        path.write_text(text, encoding="utf-8")
        return path

    return make


def problems_loading(path: Path | str, overrides: tuple[str, ...] = ()) -> list[tuple[str, str]]:
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path, overrides)
    assert caught.value.file == str(path)
    return list(caught.value.problems)


def test_loads_a_valid_scenario(write: WriteScenario) -> None:
    path = write(VALID)
    scenario = load_scenario(path)
    assert scenario == Scenario(
        path=path,
        app_path="tests.scenario.fake_app",
        app=fake_app.app,
        run=RunConfig(seed=7, virtual=True, transport="memory"),
        world=WorldConfig(width=200.0, height=100.5),
        config=FakeConfig(robots=RobotsConfig(count=40, speed=2.5)),
        data={
            "app": "tests.scenario.fake_app",
            "run": {"seed": 7, "virtual": True, "transport": "memory"},
            "world": {"width": 200, "height": 100.5},
            "robots": {"count": 40, "speed": 2.5},
        },
    )


def test_run_and_app_sections_take_their_defaults(write: WriteScenario) -> None:
    scenario = load_scenario(str(write(MINIMAL)))
    assert scenario.run == RunConfig()
    assert scenario.run == RunConfig(
        seed=0,
        virtual=False,
        time_factor=50.0,
        transport="udp",
        max_time=3600.0,
        trace_interval=1.0,
        progress_interval=1.0,
    )
    assert scenario.config == FakeConfig()


def test_app_attribute_after_a_colon(write: WriteScenario) -> None:
    text = MINIMAL.replace('"tests.scenario.fake_app"', '"tests.scenario.fake_app:other"')
    scenario = load_scenario(write(text))
    assert scenario.app is fake_app.other
    assert scenario.app_path == "tests.scenario.fake_app:other"


@pytest.mark.parametrize(
    ("run", "key", "message"),
    [
        pytest.param("seed = -1", "run.seed", "expected an integer >= 0, got -1", id="seed"),
        pytest.param(
            'virtual = "yes"',
            "run.virtual",
            'expected true or false, got "yes" (a string)',
            id="virtual",
        ),
        pytest.param(
            "time_factor = 0", "run.time_factor", "expected a number > 0, got 0", id="time-factor"
        ),
        pytest.param(
            'transport = "tcp"',
            "run.transport",
            'expected one of "udp", "memory", "zenoh", got "tcp"',
            id="transport",
        ),
        pytest.param("max_time = -5", "run.max_time", "expected a number > 0, got -5", id="max"),
        pytest.param(
            "trace_interval = 0", "run.trace_interval", "expected a number > 0, got 0", id="trace"
        ),
        pytest.param(
            "progress_interval = -1",
            "run.progress_interval",
            "expected a number > 0, got -1",
            id="progress",
        ),
        pytest.param(
            "sede = 1",
            "run",
            "unknown key 'sede' (did you mean 'seed'? expected one of: credit, max_time, "
            "partition, pass_objects, progress_interval, restart_window, restarts, seed, "
            "time_factor, trace_exchanges, trace_interval, transport, virtual, window_limit)",
            id="unknown",
        ),
    ],
)
def test_run_table_is_validated(write: WriteScenario, run: str, key: str, message: str) -> None:
    assert problems_loading(write(f"{MINIMAL}\n[run]\n{run}\n")) == [(key, message)]


def test_world_is_required(write: WriteScenario) -> None:
    assert problems_loading(write('app = "tests.scenario.fake_app"')) == [
        ("world.width", "missing required key (expected a number > 0)"),
        ("world.height", "missing required key (expected a number > 0)"),
    ]


def test_problems_of_every_section_are_reported_together(write: WriteScenario) -> None:
    text = """
        app = "tests.scenario.fake_app"
        run = {time_factor = 0}
        world = {width = -1, height = 1}
        [robots]
        count = 0
        sped = 1
    """
    assert problems_loading(write(text)) == [
        ("run.time_factor", "expected a number > 0, got 0"),
        ("world.width", "expected a number > 0, got -1"),
        ("robots", "unknown key 'sped' (did you mean 'speed'? expected one of: count, speed)"),
        ("robots.count", "expected an integer >= 1, got 0"),
    ]


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        pytest.param(
            MINIMAL + "[robot]\ncount = 3\n",
            [
                (
                    "",
                    "unknown key 'robot' (did you mean 'robots'? "
                    "expected one of: app, faults, label, layers, network, robots, run, world)",
                )
            ],
            id="app-section",
        ),
        pytest.param(
            'app = "tests.scenario.fake_app"\n[wrold]\nwidth = 1\nheight = 1\n',
            [
                ("world.width", "missing required key (expected a number > 0)"),
                ("world.height", "missing required key (expected a number > 0)"),
                (
                    "",
                    "unknown key 'wrold' (did you mean 'world'? "
                    "expected one of: app, faults, label, layers, network, robots, run, world)",
                ),
            ],
            id="runner-section",
        ),
    ],
)
def test_unknown_top_level_keys_suggest_every_section(
    write: WriteScenario, text: str, expected: list[tuple[str, str]]
) -> None:
    assert problems_loading(write(text)) == expected


def test_run_and_world_are_checked_even_when_the_app_is_not_found(write: WriteScenario) -> None:
    text = 'app = "tests.scenario.missing"\nrun = {seed = -1}\n[robots]\nanything = 1\n'
    assert problems_loading(write(text)) == [
        (
            "app",
            "cannot import \"tests.scenario.missing\": No module named 'tests.scenario.missing'",
        ),
        ("run.seed", "expected an integer >= 0, got -1"),
        ("world.width", "missing required key (expected a number > 0)"),
        ("world.height", "missing required key (expected a number > 0)"),
    ]


@pytest.mark.parametrize(
    ("app_line", "message"),
    [
        pytest.param(
            "",
            'missing required key (expected an import path such as "package.module" '
            'or "package.module:attr")',
            id="missing",
        ),
        pytest.param(
            "app = 3",
            'expected an import path such as "package.module" or "package.module:attr", got 3',
            id="not-a-string",
        ),
        pytest.param(
            'app = "not a path"',
            'expected an import path such as "package.module" or "package.module:attr", '
            'got "not a path"',
            id="malformed",
        ),
        pytest.param(
            'app = ".relative"',
            'expected an import path such as "package.module" or "package.module:attr", '
            'got ".relative"',
            id="relative",
        ),
        pytest.param(
            'app = "tests.scenario.nope"',
            "cannot import \"tests.scenario.nope\": No module named 'tests.scenario.nope'",
            id="no-module",
        ),
        pytest.param(
            'app = "tests.scenario.fake_app:nope"',
            "module \"tests.scenario.fake_app\" has no attribute 'nope'",
            id="no-attribute",
        ),
        pytest.param(
            'app = "tests.scenario.fake_app:no_robots"',
            'app "tests.scenario.fake_app:no_robots" lacks robots(config) -> Mapping[str, int]: '
            "how many robots a configuration builds, by the key that sets each number, so that "
            "the loader checks this machine holds them before anything is built "
            "(see cas_async.scenario.SimulationApp)",
            id="no-robots",
        ),
        pytest.param(
            'app = "tests.scenario.fake_app:clashing"',
            '"tests.scenario.fake_app:clashing": config_type may not have keys run, world',
            id="config-type-clashes",
        ),
        pytest.param(
            'app = "tests.scenario.fake_app:untyped"',
            '"tests.scenario.fake_app:untyped": '
            "config_type must be a dataclass, got <class 'dict'>",
            id="config-type-not-dataclass",
        ),
    ],
)
def test_bad_app(write: WriteScenario, app_line: str, message: str) -> None:
    text = f"{app_line}\n[world]\nwidth = 1\nheight = 1\n"
    assert problems_loading(write(text)) == [("app", message)]


def test_an_object_that_is_no_app_is_told_every_member_it_lacks(write: WriteScenario) -> None:
    text = 'app = "tests.scenario.fake_app:not_an_app"\n[world]\nwidth = 1\nheight = 1\n'
    problems = problems_loading(write(text))
    assert [key for key, _ in problems] == ["app"] * 5
    lacking = [message.split(" lacks ")[1].split(":")[0] for _, message in problems]
    assert lacking == [
        "name",
        "config_type",
        "robots(config) -> Mapping[str, int]",
        "check(config, world) -> None",
        "build(setup",
    ]
    assert all(
        message.startswith('app "tests.scenario.fake_app:not_an_app" lacks ')
        for _, message in problems
    )


def test_members_of_the_wrong_kind_are_named(write: WriteScenario) -> None:
    text = 'app = "tests.scenario.fake_app:not_callable"\n[world]\nwidth = 1\nheight = 1\n'
    assert problems_loading(write(text)) == [
        (
            "app",
            "app \"tests.scenario.fake_app:not_callable\" has build = 'robots go here', which "
            "is not a method; expected build(setup: SimulationSetup) -> Mission: builds the "
            "robots, adds them to setup.environment and says what the mission is for "
            "(see cas_async.scenario.SimulationApp)",
        ),
        (
            "app",
            'app "tests.scenario.fake_app:not_callable" has item_name = 3, which is not text; '
            "expected item_name: str, what a target's items are (default 'item') "
            "(see cas_async.scenario.SimulationApp)",
        ),
    ]


def test_robot_counts_that_are_no_counts_are_the_app_s_fault(write: WriteScenario) -> None:
    text = 'app = "tests.scenario.fake_app:wrong_counts"\n[world]\nwidth = 1\nheight = 1\n'
    assert problems_loading(write(text)) == [
        (
            "app",
            'app "tests.scenario.fake_app:wrong_counts": robots(config) returned '
            "{'robots.count': 'three'}; expected robot counts by the key that sets each, "
            'such as {"robots.count": 5}',
        )
    ]


def test_the_protocol_and_the_loader_agree_on_the_members() -> None:
    from cas_async.scenario import SimulationApp
    from cas_async.scenario._spec._app import APP_MEMBERS

    declared = {
        name
        for name in (*SimulationApp.__annotations__, *vars(SimulationApp))
        if not name.startswith("_")
    }
    required = {name for name, (needed, _) in APP_MEMBERS.items() if needed}
    assert declared == required
    assert all(name in (SimulationApp.__doc__ or "") for name in APP_MEMBERS)


def test_missing_file(tmp_path: Path) -> None:
    assert problems_loading(tmp_path / "absent.toml") == [("", "no such file")]


def test_unreadable_path(tmp_path: Path) -> None:
    [(key, message)] = problems_loading(tmp_path)
    assert key == ""
    assert message.startswith("cannot read the file: ")


def test_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "latin1.toml"
    path.write_bytes('name = "café"'.encode("latin-1"))
    assert problems_loading(path) == [("", "not UTF-8 text (byte 11)")]


def test_toml_syntax_error_gives_line_and_column(write: WriteScenario) -> None:
    path = write('app = "tests.scenario.fake_app"\n[world\nwidth = 1\n')
    [(key, message)] = problems_loading(path)
    assert key == ""
    assert message.startswith("not valid TOML: ")
    assert "line 2" in message
    assert "column" in message


def test_app_check_errors_get_the_file(write: WriteScenario) -> None:
    path = write(MINIMAL + "[robots]\ncount = 101\n")
    with pytest.raises(ScenarioError) as caught:
        load_scenario(path)
    assert str(caught.value) == f"{path}: robots.count: at most 100 robots, got 101"


class TestOverrides:
    @pytest.mark.parametrize(
        ("text", "expected"),
        [
            pytest.param("robots.speed=3", ("robots.speed", 3), id="int"),
            pytest.param("robots.speed=2.5", ("robots.speed", 2.5), id="float"),
            pytest.param("run.virtual=true", ("run.virtual", True), id="bool"),
            pytest.param('label="a b"', ("label", "a b"), id="quoted-string"),
            pytest.param("strategy.name=random", ("strategy.name", "random"), id="bare-string"),
            pytest.param("start=[1, 2]", ("start", [1, 2]), id="array"),
            pytest.param(" robots . speed = 4 ", ("robots.speed", 4), id="spaces"),
            pytest.param("label=a=b", ("label", "a=b"), id="equals-in-value"),
            pytest.param("label=", ("label", ""), id="empty-value"),
            pytest.param("label=1\nrun = 2", ("label", "1\nrun = 2"), id="no-smuggled-keys"),
        ],
    )
    def test_parse(self, text: str, expected: tuple[str, Any]) -> None:
        assert parse_override(text) == expected

    @pytest.mark.parametrize(
        "text",
        [
            pytest.param("robots.speed", id="no-equals"),
            pytest.param("=3", id="empty-key"),
            pytest.param("robots..speed=3", id="empty-part"),
            pytest.param(".speed=3", id="leading-dot"),
        ],
    )
    def test_parse_errors(self, text: str) -> None:
        with pytest.raises(ScenarioError) as caught:
            parse_override(text)
        assert caught.value.problems == (
            ("--set", f"expected KEY=VALUE such as robots.speed=3, got {text!r}"),
        )

    @pytest.mark.parametrize(
        ("overrides", "expected"),
        [
            pytest.param([("run.seed", 3)], {"run": {"seed": 3}, "world": {"w": 1}}, id="replace"),
            pytest.param(
                [("run.virtual", True)],
                {"run": {"seed": 1, "virtual": True}, "world": {"w": 1}},
                id="add-key",
            ),
            pytest.param(
                [("a.b.c", 1)],
                {"run": {"seed": 1}, "world": {"w": 1}, "a": {"b": {"c": 1}}},
                id="create-tables",
            ),
            pytest.param([("world", 5)], {"run": {"seed": 1}, "world": 5}, id="replace-table"),
            pytest.param(
                [("run.seed", 2), ("run.seed", 3)],
                {"run": {"seed": 3}, "world": {"w": 1}},
                id="last-wins",
            ),
        ],
    )
    def test_apply(self, overrides: list[tuple[str, Any]], expected: dict[str, Any]) -> None:
        data = {"run": {"seed": 1}, "world": {"w": 1}}
        assert apply_overrides(data, overrides) == expected
        assert data == {"run": {"seed": 1}, "world": {"w": 1}}, "the input is not changed"

    @pytest.mark.parametrize(
        ("override", "message"),
        [
            pytest.param(
                ("run.seed.x", 1),
                "cannot set run.seed.x=1: run.seed is 1, not a table",
                id="through-int",
            ),
            pytest.param(
                ("name.first", "a"),
                'cannot set name.first="a": name is "n", not a table',
                id="through-string",
            ),
            pytest.param(
                ("items.0", 1),
                "cannot set items.0=1: items is [1, 2], not a table",
                id="through-array",
            ),
        ],
    )
    def test_apply_errors(self, override: tuple[str, Any], message: str) -> None:
        data = {"run": {"seed": 1}, "name": "n", "items": [1, 2]}
        with pytest.raises(ScenarioError) as caught:
            apply_overrides(data, [override])
        assert caught.value.problems == (("--set", message),)

    def test_every_bad_override_is_reported(self) -> None:
        with pytest.raises(ScenarioError) as caught:
            apply_overrides({"a": 1, "b": 2}, [("a.x", 1), ("b.y", 2)])
        assert [key for key, _ in caught.value.problems] == ["--set", "--set"]

    def test_load_applies_overrides(self, write: WriteScenario) -> None:
        overrides = ("robots.speed=3", "run.seed=9", "label=bare", "world.width=50")
        scenario = load_scenario(write(MINIMAL), overrides)
        assert scenario.config == FakeConfig(robots=RobotsConfig(speed=3.0), label="bare")
        assert scenario.run.seed == 9
        assert scenario.world.width == 50.0
        assert scenario.data["robots"] == {"speed": 3}
        assert scenario.data["run"] == {"seed": 9}

    def test_overridden_values_are_validated(self, write: WriteScenario) -> None:
        overrides = ("robots.speed=fast", "run.seed=-1")
        assert problems_loading(write(MINIMAL), overrides) == [
            ("run.seed", "expected an integer >= 0, got -1"),
            ("robots.speed", 'expected a number > 0, got "fast" (a string)'),
        ]

    @pytest.mark.parametrize(
        ("override", "message"),
        [
            pytest.param(
                "robots.speed",
                "expected KEY=VALUE such as robots.speed=3, got 'robots.speed'",
                id="malformed",
            ),
            pytest.param(
                "world.width.x=1",
                "cannot set world.width.x=1: world.width is 10, not a table",
                id="through-a-value",
            ),
        ],
    )
    def test_override_errors_name_the_file(
        self, write: WriteScenario, override: str, message: str
    ) -> None:
        assert problems_loading(write(MINIMAL), (override,)) == [("--set", message)]

    def test_override_can_fix_what_check_refuses(self, write: WriteScenario) -> None:
        path = write(MINIMAL + "[robots]\ncount = 101\n")
        assert load_scenario(path, ["robots.count=100"]).config.robots.count == 100


def test_virtual_time_defaults_to_the_memory_transport(tmp_path: Path) -> None:
    path = tmp_path / "virtual.toml"
    path.write_text(
        'app = "tests.scenario.fake_app"\n'
        "[run]\nvirtual = true\n"
        "[world]\nwidth = 1.0\nheight = 1.0\n"
    )
    assert load_scenario(path).run.transport == "memory"
    with pytest.raises(ScenarioError, match=r"run\.transport: virtual time needs the memory"):
        load_scenario(path, ['run.transport="udp"'])


def test_objects_are_passed_only_in_memory_and_without_faults(tmp_path: Path) -> None:
    path = tmp_path / "objects.toml"
    path.write_text(
        'app = "tests.scenario.fake_app"\n'
        "[run]\nvirtual = true\npass_objects = true\n"
        "[world]\nwidth = 1.0\nheight = 1.0\n"
    )
    assert load_scenario(path).run.pass_objects
    with pytest.raises(
        ScenarioError, match=r"run\.pass_objects: objects are passed only in memory"
    ):
        load_scenario(path, ["run.virtual=false", 'run.transport="udp"'])
    with pytest.raises(ScenarioError, match=r"run\.pass_objects: \[faults\] act on datagrams"):
        load_scenario(path, ["faults.loss=0.1"])
