from __future__ import annotations

import csv
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from cas_async import SimulationError
from cas_async.scenario.output import Trace, TraceCsv


def xy_of(*points: tuple[float, float]) -> np.ndarray:
    return np.array(points, dtype=np.float64)


@pytest.fixture
def trace() -> Trace:
    """Two robots: samples at t = 0, 1, 2 and exchange snapshots 1 and 3."""
    trace = Trace([7, 3])
    trace.sample(0.0, xy_of((0.0, 0.0), (10.0, 0.0)))
    trace.sample(1.0, xy_of((1.0, 0.5), (9.0, 0.0)))
    trace.exchange(1.0, 1, xy_of((1.0, 0.5), (9.0, 0.0)))
    trace.exchange(1.5, 3, xy_of((1.5, 0.75), (8.5, 0.0)), np.array([False, True]))
    trace.sample(2.0, xy_of((2.0, 1.0), (8.0, 0.1)), np.array([True, False]))
    return trace


def test_accessors_shape_the_samples(trace: Trace) -> None:
    assert trace.ids == (7, 3)
    assert trace.times.tolist() == [0.0, 1.0, 2.0]
    assert trace.positions.shape == (3, 2, 2)
    assert trace.positions[2].tolist() == [[2.0, 1.0], [8.0, 0.1]]
    assert trace.exchange_counts.tolist() == [1, 3]
    assert trace.exchange_counts.dtype == np.int64
    assert trace.exchange_times.tolist() == [1.0, 1.5]
    assert trace.exchange_positions.shape == (2, 2, 2)
    assert "2 robots, 3 samples, 2 exchange snapshots" in repr(trace)


def test_carriers_are_recorded_with_each_record(trace: Trace) -> None:
    assert trace.carrying.tolist() == [[False, False], [False, False], [True, False]]
    assert trace.exchange_carrying.tolist() == [[False, False], [False, True]]
    assert not trace.carrying.flags.writeable


def test_carriers_are_copied(trace: Trace) -> None:
    flags = np.array([True, True])
    trace.sample(3.0, xy_of((0.0, 0.0), (0.0, 0.0)), flags)
    flags[0] = False
    assert trace.carrying[-1].tolist() == [True, True]


def test_carriers_of_the_wrong_shape_are_refused(trace: Trace) -> None:
    with pytest.raises(SimulationError, match=r"carrying of shape \(3,\), expected \(2,\)"):
        trace.sample(3.0, xy_of((0.0, 0.0), (0.0, 0.0)), np.array([True, False, True]))
    with pytest.raises(SimulationError, match="exchange 4 has carrying of shape"):
        trace.exchange(3.0, 4, xy_of((0.0, 0.0), (0.0, 0.0)), np.array([True]))


def test_an_empty_trace_has_empty_arrays() -> None:
    trace = Trace([1, 2, 3])
    assert trace.carrying.shape == (0, 3)
    assert trace.exchange_carrying.shape == (0, 3)
    assert trace.times.shape == (0,)
    assert trace.positions.shape == (0, 3, 2)
    assert trace.exchange_counts.shape == (0,)
    assert trace.exchange_positions.shape == (0, 3, 2)


def test_ids_may_come_as_a_numpy_array() -> None:
    assert Trace(np.array([4, 5], dtype=np.int64)).ids == (4, 5)


@pytest.mark.parametrize(
    ("t", "expected_row0"),
    [
        pytest.param(0.0, [0.0, 0.0], id="exactly-first"),
        pytest.param(0.99, [0.0, 0.0], id="between-takes-earlier"),
        pytest.param(1.0, [1.0, 0.5], id="exactly-second"),
        pytest.param(100.0, [2.0, 1.0], id="after-end-takes-last"),
    ],
)
def test_at_time_takes_the_last_sample_at_or_before(
    trace: Trace, t: float, expected_row0: list[float]
) -> None:
    assert trace.at_time(t)[0].tolist() == expected_row0


@pytest.mark.parametrize(
    ("count", "expected_row0"),
    [
        pytest.param(1, [1.0, 0.5], id="exact"),
        pytest.param(2, [1.0, 0.5], id="missing-takes-previous"),
        pytest.param(3, [1.5, 0.75], id="exact-last"),
        pytest.param(99, [1.5, 0.75], id="beyond-takes-last"),
    ],
)
def test_after_exchange_takes_that_snapshot_or_the_one_before(
    trace: Trace, count: int, expected_row0: list[float]
) -> None:
    assert trace.after_exchange(count)[0].tolist() == expected_row0


def test_lookups_before_the_first_record_say_so(trace: Trace) -> None:
    with pytest.raises(SimulationError, match=r"no sample at or before t = -1\.0"):
        trace.at_time(-1.0)
    with pytest.raises(SimulationError, match="no snapshot at or before exchange 0"):
        trace.after_exchange(0)
    with pytest.raises(SimulationError, match="there are none"):
        Trace([1]).at_time(5.0)


def test_samples_are_copied_and_read_only() -> None:
    source = xy_of((1.0, 2.0))
    trace = Trace([1])
    trace.sample(0.0, source)
    source[0, 0] = 99.0
    assert trace.at_time(0.0).tolist() == [[1.0, 2.0]]
    with pytest.raises(ValueError, match="read-only"):
        trace.at_time(0.0)[0, 0] = 5.0
    with pytest.raises(ValueError, match="read-only"):
        trace.positions[0, 0, 0] = 5.0


def test_a_read_only_input_is_accepted() -> None:
    source = xy_of((1.0, 2.0))
    source.flags.writeable = False
    trace = Trace([1])
    trace.sample(0.0, source)
    assert trace.positions.tolist() == [[[1.0, 2.0]]]


def test_arrays_follow_new_records() -> None:
    trace = Trace([1])
    trace.sample(0.0, xy_of((0.0, 0.0)))
    assert trace.positions.shape == (1, 1, 2)
    trace.sample(1.0, xy_of((1.0, 0.0)))
    assert trace.positions.shape == (2, 1, 2)
    assert trace.times.tolist() == [0.0, 1.0]


@pytest.mark.parametrize(
    ("record", "message"),
    [
        pytest.param(
            lambda tr: tr.sample(0.5, xy_of((0, 0), (0, 0))), "must not decrease", id="time-back"
        ),
        pytest.param(
            lambda tr: tr.sample(float("nan"), xy_of((0, 0), (0, 0))), "finite", id="nan-time"
        ),
        pytest.param(
            lambda tr: tr.sample(3.0, xy_of((0, 0))),
            r"shape \(1, 2\), expected \(2, 2\)",
            id="rows",
        ),
        pytest.param(lambda tr: tr.sample(3.0, np.zeros((2, 3))), "expected", id="cols"),
        pytest.param(
            lambda tr: tr.exchange(3.0, 3, xy_of((0, 0), (0, 0))),
            "above the previous",
            id="same-count",
        ),
        pytest.param(
            lambda tr: tr.exchange(3.0, 0, xy_of((0, 0), (0, 0))), "at least 1", id="zero-count"
        ),
        pytest.param(
            lambda tr: tr.exchange(1.0, 4, xy_of((0, 0), (0, 0))),
            "must not decrease",
            id="exchange-time-back",
        ),
    ],
)
def test_bad_records_are_refused_and_named(
    trace: Trace, record: Callable[[Trace], None], message: str
) -> None:
    with pytest.raises(SimulationError, match=message):
        record(trace)


def test_duplicate_ids_are_refused() -> None:
    with pytest.raises(SimulationError, match=r"\[3\] more than once"):
        Trace([3, 4, 3])


def test_csv_reads_back_as_the_samples_in_time_order(trace: Trace, tmp_path: Path) -> None:
    path = tmp_path / "trace.csv"
    trace.write_csv(path)
    with path.open(newline="") as stream:
        reader = csv.reader(stream)
        assert next(reader) == ["t", "robot", "x", "y", "exchange", "carrying"]
        rows = [(float(t), int(r), float(x), float(y), e, c) for t, r, x, y, e, c in reader]
    expected = []
    records = [
        (0.0, "", trace.positions[0], "00"),
        (1.0, "", trace.positions[1], "00"),
        (1.0, "1", trace.exchange_positions[0], "00"),
        (1.5, "3", trace.exchange_positions[1], "01"),
        (2.0, "", trace.positions[2], "10"),
    ]
    for t, exchange, xy, carrying in records:
        for robot_id, (x, y), held in zip(trace.ids, xy.tolist(), carrying, strict=True):
            expected.append((t, robot_id, x, y, exchange, held))
    assert rows == expected
    assert sorted(p.name for p in tmp_path.iterdir()) == ["trace.csv"]


def test_csv_keeps_full_float_precision(tmp_path: Path) -> None:
    awkward = [0.1 + 0.2, 1 / 3, 1e-300, 123456789.123456789]
    trace = Trace([1, 2])
    trace.sample(1 / 7, np.array([awkward[:2], awkward[2:]]))
    trace.write_csv(tmp_path / "trace.csv")
    with (tmp_path / "trace.csv").open(newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert float(rows[0]["t"]) == 1 / 7
    assert [
        float(rows[0]["x"]),
        float(rows[0]["y"]),
        float(rows[1]["x"]),
        float(rows[1]["y"]),
    ] == awkward


def test_many_samples_stay_cheap() -> None:
    trace = Trace(range(200))
    xy = np.zeros((200, 2))
    for k in range(10_000):
        trace.sample(float(k), xy)
    assert trace.positions.shape == (10_000, 200, 2)
    assert trace.at_time(12_345.5) is trace.at_time(12_345.0)


def test_csv_written_as_the_trace_grows_is_the_same_file(trace: Trace, tmp_path: Path) -> None:
    whole = tmp_path / "whole.csv"
    trace.write_csv(whole)
    growing = Trace(trace.ids)
    path = tmp_path / "growing.csv"
    writer = TraceCsv(growing, path)
    growing.sample(0.0, trace.positions[0])
    growing.sample(1.0, trace.positions[1])
    writer.write_until(1.0)  # t = 1 may still get a snapshot: only t = 0 is final
    growing.exchange(1.0, 1, trace.exchange_positions[0])
    growing.exchange(1.5, 3, trace.exchange_positions[1], trace.exchange_carrying[1])
    writer.write_until(1.5)
    assert not path.exists()  # in place only once closed
    growing.sample(2.0, trace.positions[2], trace.carrying[2])
    assert writer.close() == path
    assert path.read_text() == whole.read_text()


def test_a_discarded_csv_leaves_the_previous_file(trace: Trace, tmp_path: Path) -> None:
    path = tmp_path / "trace.csv"
    path.write_text("before\n")
    writer = TraceCsv(trace, path)
    writer.write_until(1.5)
    writer.discard()
    writer.discard()
    assert path.read_text() == "before\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["trace.csv"]


def test_a_failed_write_leaves_no_temporary_file(
    trace: Trace, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def full_disk(self: TraceCsv, t: float) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(TraceCsv, "write_until", full_disk)
    with pytest.raises(OSError, match="No space left"):
        trace.write_csv(tmp_path / "trace.csv")
    assert list(tmp_path.iterdir()) == []
