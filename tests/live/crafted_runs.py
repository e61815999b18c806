"""Run directories with one thing wrong each, as a stranger could craft them (issue 44 item 4).

:data:`VARIANTS` maps a name to how a copy of a good run is damaged and what the
error must name: the file, and the line and field where there is one.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any, Final

ROBOTS: Final = 25
"""Rows per sample in the run the variants start from (the Fire Brigade of §5.8.2)."""

Damage = Callable[[Path], None]


def results(edit: Callable[[dict[str, Any]], object]) -> Damage:
    def apply(run: Path) -> None:
        data = json.loads((run / "results.json").read_text())
        edit(data)
        (run / "results.json").write_text(json.dumps(data))  # NaN and Infinity as such

    return apply


def scene(edit: Callable[[dict[str, Any]], object]) -> Damage:
    def apply(run: Path) -> None:
        data = json.loads((run / "scene.json").read_text())
        edit(data)
        (run / "scene.json").write_text(json.dumps(data))

    return apply


def raw(name: str, content: bytes) -> Damage:
    return lambda run: (run / name).write_bytes(content)


def remove(name: str) -> Damage:
    return lambda run: (run / name).unlink()


def as_dir(name: str) -> Damage:
    def apply(run: Path) -> None:
        (run / name).unlink()
        (run / name).mkdir()

    return apply


def as_fifo(name: str) -> Damage:
    def apply(run: Path) -> None:
        (run / name).unlink()
        os.mkfifo(run / name)

    return apply


def as_link(name: str, target: str | Callable[[Path], str]) -> Damage:
    def apply(run: Path) -> None:
        to = target(run) if callable(target) else target
        (run / name).unlink()
        (run / name).symlink_to(to)

    return apply


def rows(edit: Callable[[list[list[str]]], object]) -> Damage:
    """Edits ``trace.csv``'s data rows, each a list of its 6 fields."""

    def apply(run: Path) -> None:
        lines = (run / "trace.csv").read_text().splitlines()
        data = [line.split(",") for line in lines[1:]]
        edit(data)
        (run / "trace.csv").write_text("\n".join([lines[0], *(",".join(r) for r in data)]) + "\n")

    return apply


def block_t(k: int, value: str) -> Damage:
    """Sets the t of every row of block ``k`` (a sample or an exchange snapshot)."""

    def edit(data: list[list[str]]) -> None:
        for row in data[k * ROBOTS : (k + 1) * ROBOTS]:
            row[0] = value

    return rows(edit)


def cell(row: int, column: int, value: str) -> Damage:
    def edit(data: list[list[str]]) -> None:
        data[row][column] = value

    return rows(edit)


def both(*steps: Damage) -> Damage:
    def apply(run: Path) -> None:
        for step in steps:
            step(run)

    return apply


def deep(n: int) -> bytes:
    return b'{"format":"cas_async scene","x":' + b"[" * n + b"]" * n + b"}"


def _outside(run: Path) -> str:
    elsewhere = run.parent / "elsewhere.csv"
    elsewhere.write_bytes((run / "trace.csv").read_bytes())
    return str(elsewhere)


def _append(path: Path, data: bytes) -> None:
    with path.open("ab") as stream:
        stream.write(data)


def _swap(data: list[list[str]]) -> None:
    at = 3 * ROBOTS
    data[at], data[at + 1] = data[at + 1], data[at]


def _snapshots(value: str) -> Callable[[list[list[str]]], None]:
    return lambda data: [row.__setitem__(4, value) for row in data if row[4]]  # type: ignore[func-returns-value]


RESULTS = r"results\.json"
SCENE = r"scene\.json"
TRACE = r"trace\.csv"

VARIANTS: Final[dict[str, tuple[Damage, str]]] = {
    # results.json
    "results-missing": (remove("results.json"), rf"{RESULTS}: missing"),
    "results-not-json": (raw("results.json", b"{nope"), rf"{RESULTS}: not JSON"),
    "results-array": (raw("results.json", b"[1, 2]"), rf"{RESULTS}: expected a JSON object"),
    "results-dir": (as_dir("results.json"), rf"{RESULTS}: not a regular file \(a directory\)"),
    "results-deep": (raw("results.json", deep(100_000)), rf"{RESULTS}: nested deeper"),
    "results-not-utf8": (raw("results.json", b'{"a":"\xff"}'), rf"{RESULTS}: not UTF-8"),
    "results-fifo": (as_fifo("results.json"), rf"{RESULTS}: not a regular file \(a FIFO\)"),
    "results-devzero": (as_link("results.json", "/dev/zero"), rf"{RESULTS}: a link out"),
    "results-link-out": (as_link("results.json", "/etc/hostname"), rf"{RESULTS}: a link out"),
    "delivery-missing": (
        results(lambda r: r.pop("delivery_times")),
        rf"{RESULTS}: delivery_times: expected a list",
    ),
    "delivery-str": (
        results(lambda r: r.update(delivery_times=["abc"])),
        rf"{RESULTS}: delivery_times\[0\]: expected a number",
    ),
    "delivery-null": (
        results(lambda r: r.update(delivery_times=[None])),
        rf"{RESULTS}: delivery_times\[0\]: expected a number",
    ),
    "delivery-nan": (
        results(lambda r: r.update(delivery_times=[float("nan")])),
        rf"{RESULTS}: delivery_times\[0\]: expected a number .* got nan",
    ),
    "delivery-backwards": (
        results(lambda r: r.update(delivery_times=[5.0, 4.0])),
        rf"{RESULTS}: delivery_times\[1\]: expected an instant not before 5.0",
    ),
    "series-list": (results(lambda r: r.update(series=[])), rf"{RESULTS}: series: expected"),
    "series-value-str": (
        results(lambda r: [v["value"].__setitem__(0, "abc") for v in r["series"].values()]),
        rf"{RESULTS}: series.line_share.value\[0\]: expected a number or null, got 'abc'",
    ),
    "series-value-object": (
        results(lambda r: [v["value"].__setitem__(0, {}) for v in r["series"].values()]),
        rf"{RESULTS}: series.line_share.value\[0\]: expected a number or null, got an object",
    ),
    "groups-list": (
        results(lambda r: r.update(groups=[1, 2])),
        rf"{RESULTS}: groups: expected an object of robot-id lists, got a list",
    ),
    "groups-member-str": (
        results(lambda r: r.update(groups={"Sink": ["x"]})),
        rf"{RESULTS}: groups.Sink\[0\]: expected a robot id",
    ),
    "groups-member-int": (
        results(lambda r: r.update(groups={"Sink": 5})),
        rf"{RESULTS}: groups.Sink: expected a list of robot ids",
    ),
    "seed-str": (results(lambda r: r.update(seed="abc")), rf"{RESULTS}: seed: expected an integer"),
    "seed-nan": (
        results(lambda r: r.update(seed=float("nan"))),
        rf"{RESULTS}: seed: expected an integer",
    ),
    "seed-inf": (
        results(lambda r: r.update(seed=float("inf"))),
        rf"{RESULTS}: seed: expected an integer",
    ),
    "seed-bool": (results(lambda r: r.update(seed=True)), rf"{RESULTS}: seed: expected an integer"),
    "target-str": (
        results(lambda r: r.update(target="abc")),
        rf"{RESULTS}: target: expected an integer",
    ),
    "makespan-str": (
        results(lambda r: r.update(makespan="soon")),
        rf"{RESULTS}: makespan: expected a number",
    ),
    "config-list-no-scene": (
        both(results(lambda r: r.update(config=[])), remove("scene.json")),
        rf"{RESULTS}: config: expected an object",
    ),
    "config-width-str-no-scene": (
        both(results(lambda r: r["config"]["world"].update(width="abc")), remove("scene.json")),
        rf"{RESULTS}: config.world.width: expected a number",
    ),
    # scene.json
    "scene-not-json": (raw("scene.json", b"{nope"), rf"{SCENE}: not JSON"),
    "scene-deep": (raw("scene.json", deep(100_000)), rf"{SCENE}: nested deeper"),
    "scene-format": (scene(lambda s: s.update(format="x")), rf"{SCENE}: format: expected"),
    "scene-no-world": (scene(lambda s: s.pop("world")), rf"{SCENE}: world: missing"),
    "scene-world-nan": (
        scene(lambda s: s["world"].update(width=float("nan"))),
        rf"{SCENE}: world.width: expected a number",
    ),
    "scene-world-negative": (
        scene(lambda s: s["world"].update(width=-10.0)),
        rf"{SCENE}: world.width: expected a number",
    ),
    "scene-world-huge": (
        scene(lambda s: s["world"].update(width=1e300)),
        rf"{SCENE}: world.width: expected a number",
    ),
    "scene-list": (scene(lambda s: s.update(scene=[])), rf"{SCENE}: scene: expected an object"),
    "scene-color": (
        scene(lambda s: s["scene"].update(colors={"line": "red"})),
        rf"{SCENE}: scene: Scene: colors\['line'\] must be '#rrggbb'",
    ),
    "scene-points": (
        scene(lambda s: s["scene"]["shapes"][0].update(points=[5, 6])),
        rf"{SCENE}: scene.shapes\[0\]",
    ),
    "scene-fifo": (as_fifo("scene.json"), rf"{SCENE}: not a regular file \(a FIFO\)"),
    "scene-devzero": (as_link("scene.json", "/dev/zero"), rf"{SCENE}: a link out"),
    "scene-dir": (as_dir("scene.json"), rf"{SCENE}: not a regular file \(a directory\)"),
    # trace.csv
    "trace-missing": (remove("trace.csv"), rf"{TRACE}: missing"),
    "trace-empty": (raw("trace.csv", b""), rf"{TRACE}: line 1: expected the header"),
    "trace-header": (raw("trace.csv", b"a,b,c\n"), rf"{TRACE}: line 1: expected the header"),
    "trace-dir": (as_dir("trace.csv"), rf"{TRACE}: not a regular file \(a directory\)"),
    "trace-fifo": (as_fifo("trace.csv"), rf"{TRACE}: not a regular file \(a FIFO\)"),
    "trace-devzero": (as_link("trace.csv", "/dev/zero"), rf"{TRACE}: a link out"),
    "trace-link-out": (as_link("trace.csv", _outside), rf"{TRACE}: a link out"),
    "trace-long-line": (
        lambda run: _append(run / "trace.csv", b"1" * 5000),
        rf"{TRACE}: line \d+: longer than 4096 bytes",
    ),
    "t-nan": (block_t(1, "nan"), rf"{TRACE}: line 27: t: expected a number from 0 to 1e\+09"),
    "t-1e300": (block_t(1, "1e300"), rf"{TRACE}: line 27: t: expected a number from 0"),
    "t-inf": (block_t(1, "inf"), rf"{TRACE}: line 27: t: expected a number from 0"),
    "t-negative": (block_t(0, "-1.0"), rf"{TRACE}: line 2: t: expected a number from 0"),
    "t-backwards": (block_t(3, "0.5"), rf"{TRACE}: line 77: t: '0.5' comes before"),
    "t-differs-in-a-sample": (cell(30, 0, "0.25"), rf"{TRACE}: line 32: t: expected the t"),
    "x-nan": (cell(0, 2, "nan"), rf"{TRACE}: line 2: x: expected a number within 1e\+12"),
    "x-1e300": (cell(0, 2, "1e300"), rf"{TRACE}: line 2: x: expected a number within"),
    "y-str": (cell(0, 3, "abc"), rf"{TRACE}: line 2: y: expected a number within .* got 'abc'"),
    "robot-str": (cell(0, 1, "abc"), rf"{TRACE}: line 2: robot: expected an integer"),
    "robot-huge": (
        rows(lambda data: [r.__setitem__(1, str(10**30)) for r in data if r[1] == "1"]),  # type: ignore[func-returns-value]
        rf"{TRACE}: line 2: robot: expected an id within 2\*\*53",
    ),
    "robot-twice": (cell(1, 1, "1"), rf"{TRACE}: line 4: robot: expected robot 1's row, got 3"),
    "exchange-str": (rows(_snapshots("abc")), rf"{TRACE}: line \d+: exchange: expected a count"),
    "exchange-negative": (rows(_snapshots("-5")), rf"{TRACE}: line \d+: exchange: expected"),
    "exchange-repeated": (rows(_snapshots("7")), rf"{TRACE}: line \d+: exchange: 7 after 7"),
    "fields-5": (rows(lambda data: data[29].pop()), rf"{TRACE}: line 31: expected 6 fields"),
    "partial-sample": (rows(lambda data: data.pop()), rf"{TRACE}: line \d+: the file ends within"),
    "rows-swapped": (rows(_swap), rf"{TRACE}: line 77: robot: expected robot"),
    "carrying-junk": (cell(0, 5, "x"), rf"{TRACE}: line 2: carrying: expected 0 or 1, got 'x'"),
}
