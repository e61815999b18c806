"""TOML tables into frozen dataclasses: every type, bounds, and messages that say where."""

from __future__ import annotations

import dataclasses
import pickle
import tomllib
from dataclasses import dataclass
from typing import Any, Literal

import pytest

from cas_async import CasError, ConfigurationError
from cas_async.scenario import ScenarioError, from_toml, setting


@dataclass(frozen=True)
class Inner:
    level: int = setting(1, ge=0)
    name: str = "inner"


@dataclass(frozen=True)
class Generator:
    rate: float = setting(gt=0, doc="items per second")
    position: tuple[float, float] = setting((0.0, 0.0), ge=0)


@dataclass(frozen=True)
class Everything:
    count: int = setting(1, ge=0, le=10)
    speed: float = setting(1.0, gt=0)
    fraction: float = setting(0.5, ge=0, le=1)
    virtual: bool = False
    name: str = "x"
    mode: Literal["udp", "memory"] = "udp"
    start: tuple[float, float] = setting((0.0, 0.0), ge=0)
    pair: tuple[int, str] = (1, "a")
    weights: tuple[float, ...] = setting((), gt=0)
    tags: list[str] = setting(default_factory=list)
    limit: float | None = setting(None, gt=0)
    inner: Inner = setting(default_factory=Inner)
    generators: tuple[Generator, ...] = ()


@dataclass(frozen=True)
class Robots:
    speed: float = setting(5.0, gt=0, doc="full speed, distance units per second")
    deceleration: float = setting(0.0, ge=0)
    range: float = setting(10.0, gt=0)


@dataclass(frozen=True)
class Area:
    width: float = setting(gt=0)
    height: float = setting(gt=0)
    inner: Inner = setting()


@dataclass(frozen=True)
class Odd:
    mapping: dict[str, int] = setting(default_factory=dict)
    either: int | str = 0


def read(cls: type[Any], text: str, key: str = "") -> Any:
    return from_toml(cls, tomllib.loads(text), key=key)


def problems_of(cls: type[Any], text: str, key: str = "") -> list[tuple[str, str]]:
    with pytest.raises(ScenarioError) as caught:
        read(cls, text, key)
    assert caught.value.file is None
    return list(caught.value.problems)


@pytest.mark.parametrize(
    ("text", "field", "expected"),
    [
        pytest.param("count = 3", "count", 3, id="int"),
        pytest.param("count = 10", "count", 10, id="int-at-upper-bound"),
        pytest.param("speed = 2.5", "speed", 2.5, id="float"),
        pytest.param("fraction = 0", "fraction", 0.0, id="float-at-lower-bound"),
        pytest.param("fraction = 1.0", "fraction", 1.0, id="float-at-upper-bound"),
        pytest.param("virtual = true", "virtual", True, id="bool"),
        pytest.param('name = "robot"', "name", "robot", id="str"),
        pytest.param('mode = "memory"', "mode", "memory", id="literal"),
        pytest.param("start = [1, 2.5]", "start", (1.0, 2.5), id="fixed-tuple"),
        pytest.param('pair = [2, "b"]', "pair", (2, "b"), id="mixed-tuple"),
        pytest.param("weights = [1, 2, 3.5]", "weights", (1.0, 2.0, 3.5), id="variadic-tuple"),
        pytest.param("weights = []", "weights", (), id="empty-variadic-tuple"),
        pytest.param('tags = ["a", "b"]', "tags", ["a", "b"], id="list"),
        pytest.param("limit = 3", "limit", 3.0, id="optional-given"),
        pytest.param("", "limit", None, id="optional-default"),
        pytest.param("[inner]\nlevel = 2", "inner", Inner(level=2), id="sub-table"),
        pytest.param("inner = {name = 'n'}", "inner", Inner(name="n"), id="inline-table"),
        pytest.param(
            "[[generators]]\nrate = 1\n[[generators]]\nrate = 2\nposition = [3, 4]",
            "generators",
            (Generator(rate=1.0), Generator(rate=2.0, position=(3.0, 4.0))),
            id="array-of-tables",
        ),
    ],
)
def test_reads_each_type(text: str, field: str, expected: object) -> None:
    value = getattr(read(Everything, text), field)
    assert value == expected
    assert type(value) is type(expected)


@pytest.mark.parametrize(
    ("text", "key", "message"),
    [
        pytest.param(
            "count = true",
            "count",
            "expected an integer >= 0 and <= 10, got true (a boolean)",
            id="int-rejects-bool",
        ),
        pytest.param(
            "count = 2.0",
            "count",
            "expected an integer >= 0 and <= 10, got 2.0 (a float)",
            id="int-rejects-float",
        ),
        pytest.param(
            "count = 11", "count", "expected an integer >= 0 and <= 10, got 11", id="int-above-le"
        ),
        pytest.param("speed = -1", "speed", "expected a number > 0, got -1", id="float-below-gt"),
        pytest.param("speed = 0", "speed", "expected a number > 0, got 0", id="float-at-gt"),
        pytest.param(
            'speed = "fast"',
            "speed",
            'expected a number > 0, got "fast" (a string)',
            id="float-rejects-string",
        ),
        pytest.param(
            "speed = false",
            "speed",
            "expected a number > 0, got false (a boolean)",
            id="float-rejects-bool",
        ),
        pytest.param(
            "speed = nan", "speed", "expected a number > 0, got nan (not finite)", id="nan"
        ),
        pytest.param(
            "speed = inf", "speed", "expected a number > 0, got inf (not finite)", id="inf"
        ),
        pytest.param(
            "fraction = 1.5",
            "fraction",
            "expected a number >= 0 and <= 1, got 1.5",
            id="float-above-le",
        ),
        pytest.param(
            "virtual = 1", "virtual", "expected true or false, got 1 (an integer)", id="bool"
        ),
        pytest.param("name = 3", "name", "expected a string, got 3 (an integer)", id="str"),
        pytest.param(
            'mode = "tcp"', "mode", 'expected one of "udp", "memory", got "tcp"', id="literal"
        ),
        pytest.param(
            'mode = "upd"',
            "mode",
            'expected one of "udp", "memory", got "upd" (did you mean "udp"?)',
            id="literal-suggests",
        ),
        pytest.param(
            "mode = 1",
            "mode",
            'expected one of "udp", "memory", got 1 (an integer)',
            id="literal-wrong-type",
        ),
        pytest.param(
            "start = [1, 2, 3]",
            "start",
            "expected an array of 2 numbers >= 0, got [1, 2, 3] (3 items)",
            id="tuple-too-long",
        ),
        pytest.param(
            "start = [1]",
            "start",
            "expected an array of 2 numbers >= 0, got [1] (1 item)",
            id="tuple-too-short",
        ),
        pytest.param(
            "start = 1",
            "start",
            "expected an array of 2 numbers >= 0, got 1 (an integer)",
            id="tuple-not-array",
        ),
        pytest.param(
            "start = [1, -2]", "start[1]", "expected a number >= 0, got -2", id="tuple-bounds"
        ),
        pytest.param(
            "pair = [1, 2]", "pair[1]", "expected a string, got 2 (an integer)", id="mixed-tuple"
        ),
        pytest.param(
            "weights = [1, 0]", "weights[1]", "expected a number > 0, got 0", id="variadic-bounds"
        ),
        pytest.param(
            'tags = "a"',
            "tags",
            'expected an array of strings, got "a" (a string)',
            id="list-not-array",
        ),
        pytest.param(
            'tags = ["a", 1]', "tags[1]", "expected a string, got 1 (an integer)", id="list-item"
        ),
        pytest.param("limit = -1", "limit", "expected a number > 0, got -1", id="optional"),
        pytest.param("inner = 3", "inner", "expected a table, got 3 (an integer)", id="not-table"),
        pytest.param(
            "[inner]\nlevel = -1", "inner.level", "expected an integer >= 0, got -1", id="sub-table"
        ),
        pytest.param(
            "[[generators]]\nrate = 1\n[[generators]]\nrate = 0",
            "generators[1].rate",
            "expected a number > 0, got 0",
            id="array-of-tables-index",
        ),
        pytest.param(
            "[[generators]]\nrate = 1\nposition = [1, -1]",
            "generators[0].position[1]",
            "expected a number >= 0, got -1",
            id="array-of-tables-nested-index",
        ),
        pytest.param(
            "[[generators]]\nposition = [1, 1]",
            "generators[0].rate",
            "missing required key (expected a number > 0)",
            id="array-of-tables-missing",
        ),
        pytest.param(
            "generators = [1]",
            "generators[0]",
            "expected a table, got 1 (an integer)",
            id="array-of-non-tables",
        ),
        pytest.param(
            "generators = {rate = 1}",
            "generators",
            "expected an array of tables, got {rate = 1} (a table)",
            id="table-for-array-of-tables",
        ),
    ],
)
def test_rejects_with_key_and_expectation(text: str, key: str, message: str) -> None:
    assert problems_of(Everything, text) == [(key, message)]


@pytest.mark.parametrize(
    ("cls", "text", "key", "message"),
    [
        pytest.param(
            Robots,
            "sped = 1",
            "",
            "unknown key 'sped' (did you mean 'speed'? "
            "expected one of: deceleration, range, speed)",
            id="top-level-suggestion",
        ),
        pytest.param(
            Robots,
            "zzz = 1",
            "",
            "unknown key 'zzz' (expected one of: deceleration, range, speed)",
            id="no-close-key",
        ),
        pytest.param(
            Everything,
            "[inner]\nlevl = 1",
            "inner",
            "unknown key 'levl' (did you mean 'level'? expected one of: level, name)",
            id="in-sub-table",
        ),
        pytest.param(
            Everything,
            "[[generators]]\nrate = 1\nrat = 2",
            "generators[0]",
            "unknown key 'rat' (did you mean 'rate'? expected one of: position, rate)",
            id="in-array-of-tables",
        ),
    ],
)
def test_unknown_key_suggests_the_closest(
    cls: type[Any], text: str, key: str, message: str
) -> None:
    assert problems_of(cls, text) == [(key, message)]


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        pytest.param(
            "",
            [
                ("width", "missing required key (expected a number > 0)"),
                ("height", "missing required key (expected a number > 0)"),
                ("inner", "missing required key (expected a table)"),
            ],
            id="all-missing",
        ),
        pytest.param(
            "width = 1\n[inner]",
            [("height", "missing required key (expected a number > 0)")],
            id="one-missing",
        ),
    ],
)
def test_missing_required_keys(text: str, expected: list[tuple[str, str]]) -> None:
    assert problems_of(Area, text) == expected


FIELDS = [field.name for field in dataclasses.fields(Everything)]


def test_reports_every_problem_at_once() -> None:
    text = """
        speed = -1
        colour = "red"
        start = [1, -1]
        [inner]
        level = "high"
        [[generators]]
        rate = 0
    """
    assert problems_of(Everything, text) == [
        ("", "unknown key 'colour' (expected one of: " + ", ".join(sorted(FIELDS)) + ")"),
        ("speed", "expected a number > 0, got -1"),
        ("start[1]", "expected a number >= 0, got -1"),
        ("inner.level", 'expected an integer >= 0, got "high" (a string)'),
        ("generators[0].rate", "expected a number > 0, got 0"),
    ]


def test_others_are_neither_fields_nor_unknown() -> None:
    data = {"speed": 2, "run": {"seed": 1}, "rnge": 3}
    with pytest.raises(ScenarioError) as caught:
        from_toml(Robots, data, others=("app", "run"))
    assert caught.value.problems == (
        (
            "",
            "unknown key 'rnge' (did you mean 'range'? "
            "expected one of: app, deceleration, range, run, speed)",
        ),
    )
    assert from_toml(Robots, {"speed": 2, "run": 1}, others=("run",)) == Robots(speed=2.0)


def test_key_prefixes_every_problem() -> None:
    problems = problems_of(Robots, "speed = -1\nsped = 2", key="robots")
    assert [key for key, _ in problems] == ["robots", "robots.speed"]


def test_defaults_fill_absent_keys() -> None:
    assert read(Everything, "") == Everything()
    assert read(Area, "width = 2\nheight = 3\n[inner]") == Area(
        width=2.0, height=3.0, inner=Inner()
    )


def test_not_a_table_at_the_top() -> None:
    with pytest.raises(ScenarioError) as caught:
        from_toml(Robots, [1, 2], key="robots")  # type: ignore[arg-type]
    assert caught.value.problems == (("robots", "expected a table, got [1, 2] (an array)"),)


def test_long_values_are_cut_short_in_messages() -> None:
    [(_, message)] = problems_of(Everything, f'name = ["{"x" * 200}"]')
    assert message == f'expected a string, got ["{"x" * 57}… (an array)'


@pytest.mark.parametrize(
    "text",
    [
        pytest.param("mapping = {a = 1}", id="dict"),
        pytest.param("either = 1", id="union"),
    ],
)
def test_unsupported_field_types_are_a_programming_error(text: str) -> None:
    with pytest.raises(TypeError, match="cannot be read from TOML"):
        read(Odd, text)


def test_from_toml_needs_a_dataclass() -> None:
    with pytest.raises(TypeError, match="needs a dataclass"):
        from_toml(dict, {})


class TestSetting:
    def test_keeps_doc_and_default(self) -> None:
        field = {field.name: field for field in dataclasses.fields(Robots)}["speed"]
        assert field.metadata["doc"] == "full speed, distance units per second"
        assert field.default == 5.0

    def test_without_default_is_required(self) -> None:
        with pytest.raises(TypeError):
            Area()

    def test_default_factory(self) -> None:
        assert Everything().tags == []
        assert Everything().tags is not Everything().tags

    def test_default_and_factory_together_are_refused(self) -> None:
        with pytest.raises(ValueError, match="both default and default_factory"):
            setting(1, default_factory=list)


class TestScenarioError:
    def test_is_a_configuration_error(self) -> None:
        assert issubclass(ScenarioError, ConfigurationError)
        assert issubclass(ScenarioError, CasError)

    @pytest.mark.parametrize(
        ("file", "problems", "text"),
        [
            pytest.param(
                "scenarios/x.toml",
                [("robots.speed", "expected a number > 0, got -1")],
                "scenarios/x.toml: robots.speed: expected a number > 0, got -1",
                id="with-file",
            ),
            pytest.param(
                None,
                [("robots.speed", "expected a number > 0, got -1")],
                "robots.speed: expected a number > 0, got -1",
                id="without-file",
            ),
            pytest.param("x.toml", [("", "no such file")], "x.toml: no such file", id="whole-file"),
            pytest.param(
                "x.toml",
                [("a", "first"), ("b[0]", "second")],
                "x.toml: a: first\nx.toml: b[0]: second",
                id="one-line-each",
            ),
        ],
    )
    def test_str(self, file: str | None, problems: list[tuple[str, str]], text: str) -> None:
        assert str(ScenarioError(problems, file)) == text

    def test_with_file(self) -> None:
        error = ScenarioError([("a", "wrong")])
        located = error.with_file("s.toml")
        assert (located.file, located.problems) == ("s.toml", (("a", "wrong"),))
        assert error.file is None
        assert str(located) == "s.toml: a: wrong"

    def test_pickles(self) -> None:
        error = pickle.loads(pickle.dumps(ScenarioError([("a", "wrong")], "s.toml")))
        assert (error.file, error.problems, str(error)) == (
            "s.toml",
            (("a", "wrong"),),
            "s.toml: a: wrong",
        )
