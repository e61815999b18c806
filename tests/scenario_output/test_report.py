from __future__ import annotations

import dataclasses
import datetime
import json
import os
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from cas_async.scenario import RunResult, RunStatus
from cas_async.scenario.output import results_dict, statistics, summary_table, write_results


def make_result(**changes: object) -> RunResult:
    result = RunResult(
        scenario="scenarios/thesis_5_8_1.toml",
        app="Fire Brigade",
        item_name="bucket",
        seed=3,
        target=4,
        created=5,
        delivered=4,
        exchanges=11,
        makespan=231.44,
        sim_time=231.44,
        wall_time=3.21,
        travel_times=[30.0, 35.0, 40.0, 70.2],
        handovers_per_item=[2, 3, 3, 6],
        distance={12: 30.1, 4: 10.0, 5: 2.5},
        messages_internal={"ChangeStatus": 812, "CompletionStatus": 301, "Pick": 1_000},
        messages_external={"RequestPartner": 190, "Meet": 57},
        protocol_errors={},
        groups={"Generator": [1], "Transporter": [4, 5, 12], "Sink": [2]},
        config={"run": {"seed": 3}, "world": {"size": [100.0, 50.0]}},
        extra={"idle_fraction": 0.25, "refills": 3},
    )
    return dataclasses.replace(result, **changes)  # type: ignore[arg-type]


# -- statistics ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("values", "expected"),
    [
        pytest.param(
            [],
            {"count": 0, "mean": None, "median": None, "p95": None, "min": None, "max": None},
            id="empty",
        ),
        pytest.param(
            [4.0],
            {"count": 1, "mean": 4.0, "median": 4.0, "p95": 4.0, "min": 4.0, "max": 4.0},
            id="one",
        ),
        pytest.param(
            [3, 1, 2],
            {"count": 3, "mean": 2.0, "median": 2, "p95": 3, "min": 1, "max": 3},
            id="odd-unsorted",
        ),
        pytest.param(
            [1, 2, 3, 4],
            {"count": 4, "mean": 2.5, "median": 2.5, "p95": 4, "min": 1, "max": 4},
            id="even-median-averages",
        ),
        # nearest rank: ceil(0.95 * 20) = 19 -> the 19th smallest, not the 20th
        pytest.param(
            list(range(1, 21)),
            {"count": 20, "mean": 10.5, "median": 10.5, "p95": 19, "min": 1, "max": 20},
            id="twenty-p95-is-19th",
        ),
        # ceil(0.95 * 10) = 10 -> the largest
        pytest.param(
            list(range(10, 0, -1)),
            {"count": 10, "mean": 5.5, "median": 5.5, "p95": 10, "min": 1, "max": 10},
            id="ten-p95-is-max",
        ),
        # ceil(0.95 * 100) = 95
        pytest.param(
            [float(v) for v in range(100)],
            {"count": 100, "mean": 49.5, "median": 49.5, "p95": 94.0, "min": 0.0, "max": 99.0},
            id="hundred-p95-is-95th",
        ),
        # ceil(0.95 * 21) = ceil(19.95) = 20
        pytest.param(
            list(range(1, 22)),
            {"count": 21, "mean": 11.0, "median": 11, "p95": 20, "min": 1, "max": 21},
            id="twenty-one",
        ),
    ],
)
def test_statistics(values: list[float], expected: dict[str, float | None]) -> None:
    assert statistics(values) == expected


# -- results.json ----------------------------------------------------------------------


_OBJECTIVE_ONLY = {"kind", "verb", "detail", "samples"}
"""Fields an item mission's results.json leaves out (it is as it was before objectives)."""
_ITEM_ONLY = {"created", "exchanges", "travel_times", "handovers_per_item"}


def test_results_dict_holds_every_field_and_the_statistics() -> None:
    result = make_result()
    data = results_dict(result)
    for field in dataclasses.fields(RunResult):
        assert (field.name in data) is (field.name not in _OBJECTIVE_ONLY), field.name
    assert data["status"] == "completed"
    assert data["distance"] == {"4": 10.0, "5": 2.5, "12": 30.1}
    assert list(data["distance"]) == ["4", "5", "12"]
    stats = data["statistics"]
    assert stats["travel_time"]["median"] == 37.5
    assert stats["handovers_per_item"]["max"] == 6
    assert stats["distance"]["total"] == pytest.approx(42.6)
    assert stats["distance"]["count"] == 3
    assert stats["messages"] == {"internal": 2_113, "external": 247}
    assert stats["protocol_errors"] == 0
    assert list(data)[:5] == ["app", "item_name", "scenario", "seed", "status"]


def test_results_dict_of_an_objective_of_its_own_has_its_samples_and_no_item_fields() -> None:
    result = make_result()
    result.kind, result.verb, result.detail = "boxes", "moved", "joint carries"
    result.samples = {"time_per_object": [4.0, 6.0, 11.0]}
    data = results_dict(result)
    for field in dataclasses.fields(RunResult):
        wanted = field.name not in _ITEM_ONLY and field.name != "detail"
        assert (field.name in data) is wanted, field.name
    assert (data["kind"], data["verb"]) == ("boxes", "moved")
    assert data["statistics"]["time_per_object"]["median"] == 6.0
    assert "travel_time" not in data["statistics"]
    table = summary_table(result)
    assert "buckets moved" in table
    assert "time per object" in table
    assert "hand-overs" not in table


def test_results_dict_makes_toml_dates_json_ready() -> None:
    config = {"when": datetime.date(2024, 5, 1), "at": [datetime.time(12, 30)], "pair": (1, 2)}
    data = results_dict(make_result(config=config))
    assert data["config"] == {"when": "2024-05-01", "at": ["12:30:00"], "pair": [1, 2]}
    json.dumps(data)


def test_results_dict_turns_numpy_numbers_into_python_ones() -> None:
    result = make_result(
        handovers_per_item=[np.int64(2), np.int64(4)], extra={"ratio": np.float32(0.5)}
    )
    data = results_dict(result)
    assert json.loads(json.dumps(data))["handovers_per_item"] == [2, 4]
    assert type(data["extra"]["ratio"]) is float


def test_results_json_round_trips(tmp_path: Path) -> None:
    result = make_result(status=RunStatus.FAILED, error="layer 2 of robot 4 raised", makespan=None)
    path = write_results(result, tmp_path / "out" / "run1")
    assert path == tmp_path / "out" / "run1" / "results.json"
    data = json.loads(path.read_text(encoding="utf-8"))
    assert data == json.loads(json.dumps(results_dict(result)))
    assert data["status"] == "failed"
    assert data["error"] == "layer 2 of robot 4 raised"
    assert data["makespan"] is None
    assert data["travel_times"] == result.travel_times
    assert data["handovers_per_item"] == result.handovers_per_item
    assert {int(k): v for k, v in data["distance"].items()} == result.distance
    assert data["messages_internal"] == result.messages_internal
    assert data["messages_external"] == result.messages_external
    assert data["groups"] == result.groups
    assert data["config"] == result.config
    assert data["extra"] == result.extra
    assert path.read_text(encoding="utf-8").startswith('{\n  "app": "Fire Brigade"')


def test_write_results_leaves_no_temp_files(tmp_path: Path) -> None:
    write_results(make_result(), tmp_path)
    write_results(make_result(seed=4), tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["results.json"]
    assert json.loads((tmp_path / "results.json").read_text())["seed"] == 4


def test_an_interrupted_write_keeps_the_previous_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    write_results(make_result(seed=1), tmp_path)

    def interrupted(src: object, dst: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_results(make_result(seed=2), tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["results.json"]
    assert json.loads((tmp_path / "results.json").read_text())["seed"] == 1


# -- the summary table -------------------------------------------------------------------


def test_summary_table_of_a_completed_run() -> None:
    table = summary_table(make_result())
    lines = table.splitlines()
    assert lines[0] == "Fire Brigade — scenarios/thesis_5_8_1.toml, seed 3: completed"
    assert lines[1:] == [
        "makespan              231.4 s simulated   (wall 3.2 s)",
        "buckets delivered     4 of 4              (created 5, exchanges 11)",
        "bucket travel time    mean 43.8  median 37.5  p95 70.2 s",
        "hand-overs per bucket mean 3.5  median 3  max 6",
        "distance per robot    mean 14.2  max 30.1  total 42.6",
        "messages internal     Pick 1,000, ChangeStatus 812, CompletionStatus 301 (total 2,113)",
        "messages external     RequestPartner 190, Meet 57 (total 247)",
        "messages dropped      none",
        "robots                Generator 1, Transporter 3, Sink 1",
        "idle fraction         0.25",
        "refills               3",
    ]


def test_summary_table_shows_deliveries_over_time_and_the_measures() -> None:
    result = make_result(
        sim_time=40.0,
        delivery_times=[5.0, 10.0, 10.5, 39.0],
        metrics={"line_share": 0.625},
        series={
            "line_share": {"t": [0.0, 10.0, 20.0, 30.0, 40.0], "value": [0.2, 0.4, 0.5, 0.6, 0.65]}
        },
        by_exchange={
            "line_share": {"count": [1.0, 2.0, 3.0, 4.0, 5.0], "value": [0.1, 0.2, 0.3, 0.4, 0.5]}
        },
    )
    lines = summary_table(result).splitlines()
    at = lines.index("buckets delivered by  10.0 s: 2, 20.0 s: 3, 30.0 s: 3, 40.0 s: 4")
    assert lines[at + 1 : at + 3] == [
        "line share            last third 0.62, by quarter 0.30 0.45 0.55 0.62,",
        "                      after exchange 1: 0.10 2: 0.20 4: 0.40 5: 0.50",
    ]
    data = results_dict(result)
    assert data["metrics"] == {"line_share": 0.625}
    assert data["series"]["line_share"]["value"][-1] == 0.65
    assert data["by_exchange"]["line_share"]["count"] == [1.0, 2.0, 3.0, 4.0, 5.0]
    assert data["delivery_times"] == [5.0, 10.0, 10.5, 39.0]


def test_scalars_are_what_a_sweep_tabulates() -> None:
    result = make_result(metrics={"line_share": 0.5}, extra={"strategy": "time", "refills": 3})
    assert result.scalars() == {
        "makespan": 231.44,
        "sim_time": 231.44,
        "delivered": 4.0,
        "exchanges": 11.0,
        "exchanges_per_item": 3.5,
        "travel_time": pytest.approx(43.8),
        "distance": pytest.approx(14.2),
        "wall_time": 3.21,
        "line_share": 0.5,
        "refills": 3.0,
    }
    assert "makespan" not in make_result(makespan=None).scalars()


def test_summary_table_of_an_unfinished_run_says_so() -> None:
    result = make_result(
        status=RunStatus.TIMED_OUT,
        makespan=None,
        sim_time=600.0,
        delivered=2,
        travel_times=[],
        handovers_per_item=[],
        distance={},
        protocol_errors={"late_reply": 2, "unknown_type": 5},
    )
    table = summary_table(result)
    assert table.splitlines()[0].endswith(": TIMED OUT (max_time reached before the target)")
    assert "makespan              not reached (ran 600.0 s simulated)" in table
    assert "buckets delivered     2 of 4" in table
    assert "bucket travel time    n/a (no values)" in table
    assert "distance per robot    n/a (no values)" in table
    assert "messages dropped      unknown_type 5, late_reply 2" in table


def test_summary_table_shows_the_error_of_a_failed_run() -> None:
    table = summary_table(make_result(status=RunStatus.FAILED, error="boom in layer 1"))
    assert "FAILED" in table.splitlines()[0]
    assert "error                 boom in layer 1" in table


def test_summary_table_wraps_long_message_lists() -> None:
    many = {f"MessageNumber{k:02d}": 100 - k for k in range(12)}
    lines = summary_table(make_result(messages_internal=many)).splitlines()
    start = next(k for k, line in enumerate(lines) if line.startswith("messages internal"))
    assert all(len(line) <= 100 for line in lines[start : start + 4])
    assert lines[start + 1].startswith(" " * 22 + "MessageNumber")
    assert "(total 1,134)" in "\n".join(lines)


@pytest.mark.parametrize(
    ("item_name", "plural"),
    [
        ("bucket", "buckets"),
        ("box", "boxes"),
        ("battery", "batteries"),
        ("tray", "trays"),
        ("fire extinguisher", "fire extinguishers"),
    ],
)
def test_summary_table_uses_the_item_name(item_name: str, plural: str) -> None:
    lines = summary_table(make_result(item_name=item_name)).splitlines()[1:]
    assert any(line.startswith(f"{plural} delivered ") for line in lines)
    assert any(re.match(rf"hand-overs per {item_name} +mean", line) for line in lines)
    # however long the labels, the values start in one column
    column = max(22, len(f"hand-overs per {item_name} "))
    assert {line.index("mean") for line in lines if " mean " in line} == {column}


# -- what extra holds ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "kept"),
    [
        pytest.param(3, 3, id="int"),
        pytest.param(0.25, 0.25, id="float"),
        pytest.param("time", "time", id="str"),
        pytest.param(True, True, id="bool"),
        pytest.param(np.int64(7), 7, id="numpy-int"),
        pytest.param(np.float32(0.5), 0.5, id="numpy-float"),
        pytest.param(np.bool_(False), False, id="numpy-bool"),
    ],
)
def test_extra_holds_one_figure_per_name(value: object, kept: object) -> None:
    result = make_result(extra={})
    result.extra["figure"] = value  # type: ignore[assignment]
    assert result.extra["figure"] == kept
    assert type(result.extra["figure"]) is type(kept)  # a Python value: JSON and the table


SET_WAYS = {
    "item": lambda extra, value: extra.__setitem__("by_robot", value),
    "update": lambda extra, value: extra.update(by_robot=value),
    "setdefault": lambda extra, value: extra.setdefault("by_robot", value),
    "ior": lambda extra, value: extra.__ior__({"by_robot": value}),
}


@pytest.mark.parametrize("way", SET_WAYS.values(), ids=SET_WAYS.keys())
@pytest.mark.parametrize(
    ("value", "kind"),
    [
        pytest.param({1: 4, 2: 4}, "dict", id="dict"),
        pytest.param([1.0, 2.0], "list", id="list"),
        pytest.param(None, "NoneType", id="none"),
        pytest.param(np.array([1, 2]), "numpy.ndarray", id="array"),
    ],
)
def test_extra_refuses_what_is_not_one_figure_where_it_is_set(
    way: Callable[[dict[str, object], object], object], value: object, kind: str
) -> None:
    result = make_result()
    with pytest.raises(TypeError) as refused:
        way(result.extra, value)  # type: ignore[arg-type]
    line = str(refused.value)
    assert line.startswith(f"RunResult.extra['by_robot'] = {value!r}: not one figure ({kind}); ")
    assert "a number (int, float), a str or a bool" in line
    assert "\n" not in line
    assert "by_robot" not in result.extra


def test_extra_given_whole_is_checked_too() -> None:
    with pytest.raises(TypeError, match=r"RunResult\.extra\['cells'\] = \{1: 4\}: not one"):
        make_result(extra={"cells": {1: 4}})
    result = make_result()
    with pytest.raises(TypeError, match=r"RunResult\.extra\[3\]: the key is not a str \(int\)"):
        result.extra = {3: 1.0}  # type: ignore[dict-item]
    result.extra = {"refills": np.int64(2)}  # type: ignore[dict-item]
    assert result.extra == {"refills": 2}


def test_the_summary_shows_any_value_a_result_holds() -> None:
    result = make_result()
    dict.__setitem__(result.extra, "cells_by_robot", {1: 4, 2: 4})  # past the check
    dict.__setitem__(result.extra, "ratio", np.float32(0.5))
    lines = summary_table(result).splitlines()
    assert lines[-2:] == ["cells by robot        {1: 4, 2: 4}", "ratio                 0.5"]
