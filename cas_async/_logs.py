"""Loggers that name the robot and layer, and drop logging that cannot flood.

All records go to the ``cas_async`` logger hierarchy; nothing is configured here
(that is the application's choice). Prefixes are fixed when a robot starts, so
logging a message formats nothing unless the level is enabled.
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import MutableMapping
from typing import Any

__all__ = ["DropLog", "PrefixLogger", "logger_for"]

_root = logging.getLogger("cas_async")


class PrefixLogger(logging.LoggerAdapter[logging.Logger]):
    """A logger adapter that starts every message with ``"robot 3 Top(L0): "``."""

    def __init__(self, logger: logging.Logger, prefix: str) -> None:
        super().__init__(logger, {})
        self.prefix = prefix

    def process(
        self, msg: Any, kwargs: MutableMapping[str, Any]
    ) -> tuple[Any, MutableMapping[str, Any]]:
        """Prefixes the message with the robot (and layer) name."""
        return f"{self.prefix}{msg}", kwargs


def logger_for(
    robot_id: int, layer_name: str | None = None, level: int | None = None
) -> PrefixLogger:
    """The logger of a robot (``cas_async.robot``) or of one of its layers (``cas_async.layer``)."""
    if layer_name is None:
        return PrefixLogger(_root.getChild("robot"), f"robot {robot_id}: ")
    return PrefixLogger(_root.getChild("layer"), f"robot {robot_id} {layer_name}(L{level}): ")


class DropLog:
    """Counts dropped messages by reason and logs them without flooding.

    A reason is logged at its 1st, 10th, 100th, ... occurrence, so a flood of a
    million bad datagrams writes six lines, and no clock is needed to rate-limit.
    """

    def __init__(self, log: PrefixLogger) -> None:
        self.counts: Counter[str] = Counter()
        self._log = log

    def drop(self, reason: str, detail: str, *, log: bool = True) -> None:
        """Counts one drop and logs it when its count reaches a power of ten."""
        counts = self.counts
        counts[reason] += 1
        n = counts[reason]
        if log and _is_power_of_ten(n):
            self._log.warning("dropped (%s, %d so far): %s", reason, n, detail)


def _is_power_of_ten(n: int) -> bool:
    while n >= 10 and n % 10 == 0:
        n //= 10
    return n == 1
