from __future__ import annotations

import io

import pytest

from cas_async.scenario.output import Progress


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0
        self.reads = 0

    def __call__(self) -> float:
        self.reads += 1
        return self.now


@pytest.fixture
def clock() -> FakeClock:
    return FakeClock()


def make(stream: io.StringIO, clock: FakeClock, *, tty: bool, target: int = 20) -> Progress:
    return Progress(stream, target=target, item_name="bucket", interval=1.0, tty=tty, now=clock)


# -- not a TTY: plain lines ------------------------------------------------------------


def test_plain_prints_a_line_every_interval(clock: FakeClock) -> None:
    stream = io.StringIO()
    progress = make(stream, clock, tty=False)
    progress.update(0.0, 0, 0)  # the first update shows at once
    for k in range(1, 100):  # within the same wall second: nothing more
        clock.now += 0.009
        progress.update(k * 0.1, 1, k)
    clock.now = 101.0
    progress.update(112.5, 9, 31)
    progress.update(113.0, 9, 32)
    assert stream.getvalue().splitlines() == [
        "t=0.0s buckets 0/20 exchanges 0",
        "t=112.5s buckets 9/20 exchanges 31",
    ]


def test_plain_close_prints_the_final_state(clock: FakeClock) -> None:
    stream = io.StringIO()
    progress = make(stream, clock, tty=False)
    progress.update(1.0, 1, 1)
    progress.update(231.4, 20, 57)  # not due: recorded only
    progress.close()
    progress.close()  # once is enough
    progress.update(300.0, 21, 60)  # ignored after close
    assert stream.getvalue().splitlines() == [
        "t=1.0s buckets 1/20 exchanges 1",
        "t=231.4s buckets 20/20 exchanges 57",
    ]


def test_plain_close_without_final_prints_nothing_more(clock: FakeClock) -> None:
    stream = io.StringIO()
    progress = make(stream, clock, tty=False)
    progress.update(1.0, 1, 1)
    progress.close(final=False)
    assert stream.getvalue() == "t=1.0s buckets 1/20 exchanges 1\n"


def test_plain_output_has_no_control_characters(clock: FakeClock) -> None:
    stream = io.StringIO()
    progress = make(stream, clock, tty=False)
    for k in range(50):
        clock.now += 0.5
        progress.update(k, k % 21, k)
    progress.close()
    text = stream.getvalue()
    assert all(ch == "\n" or ch.isprintable() for ch in text)


def test_tty_none_asks_the_stream(clock: FakeClock) -> None:
    stream = io.StringIO()  # StringIO.isatty() is False
    progress = Progress(stream, target=3, item_name="box", now=clock)
    progress.update(2.0, 1, 0)
    assert stream.getvalue() == "t=2.0s boxes 1/3 exchanges 0\n"


# -- a TTY: one redrawn line --------------------------------------------------------------


def test_tty_redraws_one_line_at_most_ten_times_a_second(clock: FakeClock) -> None:
    stream = io.StringIO()
    progress = make(stream, clock, tty=True)
    for k in range(1000):  # one wall second in 1 ms steps
        progress.update(k * 0.1, 0, 0)
        clock.now += 0.001
    assert 9 <= stream.getvalue().count("\r") <= 11
    assert "\n" not in stream.getvalue()


def test_tty_line_shows_a_bar(clock: FakeClock) -> None:
    stream = io.StringIO()
    progress = make(stream, clock, tty=True)
    progress.update(112.5, 9, 31)
    assert stream.getvalue() == (
        "\r[#########-----------]  9/20 buckets | t = 112.5 s | 31 exchanges"
    )


def test_tty_blanks_what_a_longer_line_left(clock: FakeClock) -> None:
    stream = io.StringIO()
    progress = make(stream, clock, tty=True, target=5)
    progress.update(1000.0, 1, 1000)
    clock.now += 1
    progress.update(1.0, 2, 1)
    first, second = stream.getvalue().split("\r")[1:]
    assert len(second) == len(first)
    assert second.rstrip() == "[########------------] 2/5 buckets | t = 1.0 s | 1 exchanges"


def test_tty_close_draws_the_final_state_and_ends_the_line(clock: FakeClock) -> None:
    stream = io.StringIO()
    progress = make(stream, clock, tty=True)
    progress.update(1.0, 1, 1)
    progress.update(231.4, 20, 57)  # too soon to draw
    progress.close()
    assert stream.getvalue().endswith(
        "\r[####################] 20/20 buckets | t = 231.4 s | 57 exchanges\n"
    )


def test_tty_close_without_final_only_ends_the_line(clock: FakeClock) -> None:
    stream = io.StringIO()
    progress = make(stream, clock, tty=True)
    progress.update(1.0, 1, 1)
    progress.update(2.0, 2, 2)
    progress.close(final=False)
    assert stream.getvalue() == "\r[#-------------------]  1/20 buckets | t = 1.0 s | 1 exchanges\n"


def test_tty_close_without_anything_drawn_writes_nothing(clock: FakeClock) -> None:
    stream = io.StringIO()
    make(stream, clock, tty=True).close(final=False)
    assert stream.getvalue() == ""


@pytest.mark.parametrize(
    ("target", "delivered", "bar"),
    [
        pytest.param(20, 0, "[--------------------]", id="none"),
        pytest.param(20, 20, "[####################]", id="all"),
        pytest.param(20, 25, "[####################]", id="beyond-target-clamps"),
        pytest.param(3, 1, "[######--------------]", id="third"),
        pytest.param(0, 0, "[####################]", id="zero-target-is-done"),
    ],
)
def test_tty_bar(clock: FakeClock, target: int, delivered: int, bar: str) -> None:
    stream = io.StringIO()
    make(stream, clock, tty=True, target=target).update(0.0, delivered, 0)
    assert stream.getvalue().startswith("\r" + bar)


# -- cost and arguments ---------------------------------------------------------------------


def test_updates_between_lines_write_nothing(clock: FakeClock) -> None:
    class CountingStream(io.StringIO):
        writes = 0

        def write(self, text: str) -> int:
            CountingStream.writes += 1
            return super().write(text)

    stream = CountingStream()
    progress = make(stream, clock, tty=True)
    for k in range(10_000):
        progress.update(float(k), 0, k)
    assert CountingStream.writes == 1
    assert clock.reads == 10_000


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        pytest.param({"target": -1}, "target must not be negative", id="negative-target"),
        pytest.param({"interval": 0.0}, "interval must be a positive number", id="zero-interval"),
        pytest.param({"interval": float("nan")}, "positive number", id="nan-interval"),
    ],
)
def test_bad_arguments_are_refused(kwargs: dict[str, float], message: str) -> None:
    arguments: dict[str, object] = {"target": 5, "item_name": "bucket", **kwargs}
    with pytest.raises(ValueError, match=message):
        Progress(io.StringIO(), **arguments)  # type: ignore[arg-type]
