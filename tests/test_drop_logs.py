"""Drop logs: formatted only when written, and short whatever the message dropped."""

from __future__ import annotations

import logging

import pytest

from cas_async import Message, message
from cas_async._core._logs import MAX_DETAIL, DropLog, logger_for


@message
class Bulky(Message):
    text: str
    items: list[int]


class Costly:
    """Counts how often it is formatted."""

    formatted = 0

    def __repr__(self) -> str:
        Costly.formatted += 1
        return "costly"


def test_details_are_formatted_only_for_the_lines_written(caplog: pytest.LogCaptureFixture) -> None:
    drops = DropLog(logger_for(1))
    Costly.formatted = 0
    with caplog.at_level(logging.WARNING, logger="cas_async"):
        for _ in range(1000):
            drops.drop("spoofed_sender", "external %s", Costly())
    assert drops.counts["spoofed_sender"] == 1000
    assert Costly.formatted == 4  # the 1st, 10th, 100th and 1000th
    assert len(caplog.records) == 4


def test_a_line_quotes_a_huge_message_in_a_few_hundred_characters(
    caplog: pytest.LogCaptureFixture,
) -> None:
    drops = DropLog(logger_for(1))
    bulky = Bulky("x" * 60_000, list(range(20_000)))
    with caplog.at_level(logging.WARNING, logger="cas_async"):
        drops.drop("queue_full", "inbox full, %s", bulky)
        drops.drop("transport.socket_error", "%s", "y" * 100_000)
    first, second = (record.getMessage() for record in caplog.records)
    assert "Bulky(text='xxx" in first
    assert "...]" in first  # the list is cut after a few items
    assert len(first) < MAX_DETAIL + 100
    assert len(second) < MAX_DETAIL + 100
    assert "(100000 characters)" in second
