from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

import cas_async
from cas_async.scenario.output import Trace, write_plots
from cas_async.scenario.output._plot_labels import id_labels
from cas_async.scenario.output._plots import _at_times, _exchange_picks, _spread

if TYPE_CHECKING:
    from matplotlib.figure import Figure

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
NAMES = [
    "initial_positions.png",
    "snapshots_by_exchange.png",
    "snapshots_by_time.png",
    "trajectories.png",
    "over_time.png",
]
GROUPS = {"Generator": [1], "Transporter": [2, 3, 4, 5, 6], "Sink": [7]}


def walking_trace(samples: int, exchanges: int, duration: float = 80.0) -> Trace:
    """Robots 1..8 (8 in no group) drifting right; exchange snapshots between the samples."""
    trace = Trace(range(1, 9))
    start = np.column_stack([np.linspace(5, 40, 8), np.linspace(5, 45, 8)])
    events = [(t, "sample") for t in np.linspace(0, duration, samples).tolist()]
    events += [(t, "exchange") for t in np.linspace(1, duration - 1, exchanges).tolist()]
    count = 0
    for t, kind in sorted(events):
        xy = start + np.array([t * 0.2, 0.0])
        carrying = np.arange(8) == count % 8  # one carrier at a time, in turn
        if kind == "sample":
            trace.sample(t, xy, carrying)
        else:
            count += 1
            trace.exchange(t, count, xy, carrying)
    return trace


def assert_png(path: Path) -> None:
    import matplotlib.image

    assert path.read_bytes()[:8] == PNG_MAGIC
    assert path.stat().st_size < 1_000_000
    height, width = matplotlib.image.imread(path).shape[:2]
    assert height > 0
    assert width > 0


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    out_dir = tmp_path_factory.mktemp("plots") / "run" / "figures"  # created by write_plots
    # 12 exchanges fill six panels; 4 samples fill only four (the rest is left blank)
    return write_plots(
        walking_trace(samples=4, exchanges=12),
        GROUPS,
        (60.0, 50.0),
        out_dir,
        title="Test, seed 1",
        snapshot_exchanges=(3, 7, 200),
        delivery_times=(10.0, 30.0, 31.0),
        series={"spread": {"t": [0.0, 40.0, 80.0], "value": [0.1, 0.5, 0.4]}},
        item_name="box",
    )


def test_five_pngs_are_written(written: list[Path]) -> None:
    assert [path.name for path in written] == NAMES
    for path in written:
        assert_png(path)


@pytest.mark.parametrize(
    ("counts", "wanted", "expected"),
    [
        pytest.param([], (35,), [], id="no-snapshots"),
        pytest.param([1, 2, 3], (), [0, 1, 2], id="few-all"),
        pytest.param(
            list(range(1, 134)),
            (35, 95, 125, 200),
            [0, 34, 63, 94, 124, 132],
            id="thesis-counts-reached-and-the-last",
        ),
        pytest.param(list(range(1, 30)), (35, 95), [0, 6, 13, 17, 21, 28], id="none-reached"),
        pytest.param([2, 4, 40, 41], (35,), [0, 1, 2, 3], id="last-before-a-count"),
    ],
)
def test_exchange_panels_show_the_counts_asked_for_where_reached(
    counts: list[int], wanted: tuple[int, ...], expected: list[int]
) -> None:
    assert _exchange_picks(np.array(counts, dtype=np.int64), wanted, 6) == expected


def test_carriers_are_circled_and_robots_named(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from matplotlib.axes import Axes

    circled: list[int] = []
    named: list[str] = []
    scatter, annotate = Axes.scatter, Axes.annotate

    def spy_scatter(self: Axes, x: object, y: object, *args: object, **kwargs: object) -> object:
        if kwargs.get("label") == "carrying":
            circled.append(len(np.atleast_1d(x)))
        return scatter(self, x, y, *args, **kwargs)  # type: ignore[arg-type]

    def spy_annotate(self: Axes, text: str, *args: object, **kwargs: object) -> object:
        named.append(text)
        return annotate(self, text, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(Axes, "scatter", spy_scatter)
    monkeypatch.setattr(Axes, "annotate", spy_annotate)
    write_plots(walking_trace(samples=6, exchanges=6), GROUPS, (60.0, 50.0), tmp_path, title="t")
    assert circled == [1] * 12  # six panels by exchange, six by time: one carrier each
    assert {str(robot) for robot in range(1, 9)} <= set(named)


def test_without_records_each_figure_is_a_note(tmp_path: Path) -> None:
    written = write_plots(Trace([1, 2]), {}, (10.0, 10.0), tmp_path, title="empty")
    # no exchange figure at all: a run without exchanges has nothing to show there
    assert [path.name for path in written] == [n for n in NAMES if "exchange" not in n]
    for path in written:
        assert_png(path)
    assert not (tmp_path / "snapshots_by_exchange.png").exists()


def test_a_run_without_exchanges_gets_no_exchange_figure(
    tmp_path: Path, plot_notes: list[str]
) -> None:
    written = write_plots(walking_trace(samples=3, exchanges=0), GROUPS, (60.0, 50.0), tmp_path,
                          title="t")  # fmt: skip
    assert "snapshots_by_exchange.png" not in [path.name for path in written]
    assert not (tmp_path / "snapshots_by_exchange.png").exists()
    assert plot_notes == []


def test_switched_off_exchange_snapshots_are_said_so(tmp_path: Path, plot_notes: list[str]) -> None:
    written = write_plots(
        walking_trace(samples=3, exchanges=0),
        GROUPS,
        (60.0, 50.0),
        tmp_path,
        title="t",
        exchanges_traced=False,
    )
    assert "snapshots_by_exchange.png" in [path.name for path in written]
    assert len(plot_notes) == 1  # the exchange figure only: the other two have samples
    assert plot_notes[0].startswith("exchange snapshots switched off")


def figure_texts(monkeypatch: pytest.MonkeyPatch) -> dict[str, list[str]]:
    """The labels and legend entries each figure gets, by file name, once written."""
    from cas_async.scenario.output import _plots as plots

    texts: dict[str, list[str]] = {}
    save = plots._save

    def recording_save(figure: Figure, path: Path) -> Path:
        found = [t.get_text() for axes in figure.axes for t in axes.texts]
        legends = [*figure.legends, *(a.get_legend() for a in figure.axes if a.get_legend())]
        found += [f"legend:{t.get_text()}" for legend in legends for t in legend.get_texts()]
        texts[path.name] = found
        return save(figure, path)

    monkeypatch.setattr(plots, "_save", recording_save)
    return texts


@pytest.mark.slow
def test_robots_standing_together_share_one_label(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    texts = figure_texts(monkeypatch)
    trace = Trace([1, 3, 12, 31])
    together = np.array([[10.0, 10.0], [10.05, 10.0], [40.0, 20.0], [40.0, 20.3]])
    for t in (0.0, 1.0):
        trace.sample(t, together, np.zeros(4, dtype=bool))
    trace.exchange(0.5, 1, together, np.zeros(4, dtype=bool))
    write_plots(trace, {"Robot": [1, 3, 12, 31]}, (60.0, 50.0), tmp_path, title="t")
    for name in ("initial_positions.png", "snapshots_by_exchange.png", "snapshots_by_time.png"):
        labels = [text for text in texts[name] if not text.startswith("legend:")]
        assert set(labels) == {"1,3", "12,31"}, name
    # robots that did not move get a marker and a legend entry, but no label, in trajectories
    assert "1" not in texts["trajectories.png"]


def test_id_labels_part_only_robots_whose_labels_would_overlap() -> None:
    world = (100.0, 100.0)
    xy = np.array([[0.0, 0.0], [0.5, 0.0], [50.0, 50.0], [10.0, 10.0], [10.0, 30.0]])
    assert id_labels([3, 1, 2, 31, 4], xy, world) == [
        ("1,3", (0.5, 0.0)),
        ("2", (50.0, 50.0)),
        ("4", (10.0, 30.0)),
        ("31", (10.0, 10.0)),
    ]
    crowd = np.zeros((8, 2))
    assert id_labels(list(range(1, 9)), crowd, world) == [("1,2,3 +5", (0.0, 0.0))]


@pytest.mark.slow
def test_no_groups_no_other_legend(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    texts = figure_texts(monkeypatch)
    write_plots(walking_trace(samples=4, exchanges=6), {}, (60.0, 50.0), tmp_path, title="t")
    entries = [text for found in texts.values() for text in found if text.startswith("legend:")]
    assert "legend:other" not in entries
    assert set(entries) <= {"legend:carrying", "legend:boxs delivered", "legend:items delivered",
                            "legend:exchanges"}  # fmt: skip


@pytest.mark.parametrize(
    ("available", "expected"),
    [
        pytest.param(0, [], id="none"),
        pytest.param(1, [0], id="one"),
        pytest.param(4, [0, 1, 2, 3], id="fewer-than-six-all"),
        pytest.param(6, [0, 1, 2, 3, 4, 5], id="six"),
        pytest.param(11, [0, 2, 4, 6, 8, 10], id="eleven-even"),
        pytest.param(100, [0, 20, 40, 59, 79, 99], id="first-to-last"),
    ],
)
def test_exchange_panels_spread_from_first_to_last(available: int, expected: list[int]) -> None:
    assert _spread(available, 6) == expected


@pytest.mark.parametrize(
    ("times", "expected"),
    [
        pytest.param([], [], id="none"),
        pytest.param([0.0], [0], id="one"),
        pytest.param([0.0, 1.0, 2.0, 3.0, 4.0, 5.0], [0, 1, 2, 3, 4, 5], id="exact"),
        pytest.param([0.0, 1.0, 10.0], [0, 1, 2], id="gap-takes-earlier"),
        pytest.param([float(t) for t in range(101)], [0, 20, 40, 60, 80, 100], id="spread"),
    ],
)
def test_time_panels_take_the_last_sample_at_or_before(
    times: list[float], expected: list[int]
) -> None:
    assert _at_times(np.array(times, dtype=np.float64), 6) == expected


def module_level_imports(tree: ast.Module) -> Iterator[str]:
    """Modules imported when the file is imported: outside functions and ``if TYPE_CHECKING``."""
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            continue
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            yield node.module


class _TopLevel(ast.NodeTransformer):
    """Drops function bodies and ``if TYPE_CHECKING:`` blocks, which do not run on import."""

    def visit_FunctionDef(self, node: ast.FunctionDef) -> None:
        return None

    def visit_AsyncFunctionDef(self, node: ast.AsyncFunctionDef) -> None:
        return None

    def visit_If(self, node: ast.If) -> ast.AST | None:
        if isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            return None
        return self.generic_visit(node)


def test_no_cas_async_module_imports_matplotlib_on_import() -> None:
    """So ``import cas_async`` (or any of its modules) never pays for matplotlib.

    Checked on the source rather than in a fresh interpreter, which would cost
    more than every plot test together.
    """
    package = Path(cas_async.__file__).parent
    offenders = [
        f"{path.relative_to(package)}: {name}"
        for path in sorted(package.rglob("*.py"))
        for name in module_level_imports(_TopLevel().visit(ast.parse(path.read_text())))
        if name.split(".")[0] == "matplotlib"
    ]
    assert not offenders
    # the check sees a module-level import when there is one
    planted = ast.parse("import matplotlib.figure\ndef f():\n    import matplotlib\n")
    assert list(module_level_imports(_TopLevel().visit(planted))) == ["matplotlib.figure"]
