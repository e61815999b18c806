"""Loggers that name the robot and layer, and drop logging that cannot flood.

All records go to the ``cas_async`` logger hierarchy; nothing is configured here
(that is the application's choice). Prefixes are fixed when a robot starts, so
logging a message formats nothing unless the level is enabled.
"""

from __future__ import annotations

import logging
import reprlib
from collections import Counter
from collections.abc import MutableMapping
from typing import Any, Final

__all__ = ["MAX_DETAIL", "DropLog", "PrefixLogger", "brief", "logger_for"]

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


MAX_DETAIL: Final = 400
"""Characters of a drop's details a log line quotes at most."""

_BRIEF: Final = reprlib.Repr()
_BRIEF.maxstring = _BRIEF.maxother = 80
_BRIEF.maxlist = _BRIEF.maxtuple = _BRIEF.maxdict = _BRIEF.maxset = 8
_BRIEF.maxlevel = 3


def brief(value: object) -> str:
    """A short form of ``value`` for a log line: text (or an error) as is, else a capped repr.

    An object may say how it wants to be quoted with a ``__brief__()`` method (a
    message does: its fields capped, then its header).
    """
    if isinstance(value, str | BaseException):
        return str(value)
    shorter = getattr(type(value), "__brief__", None)
    return shorter(value) if shorter is not None else _BRIEF.repr(value)


class DropLog:
    """Counts dropped messages by reason and logs them without flooding.

    A reason is logged at its 1st, 10th, 100th, ... occurrence, so a flood of a
    million bad datagrams writes six lines, and no clock is needed to rate-limit.
    The details are formatted only for a line that is written, and quote at most
    :data:`MAX_DETAIL` characters: a drop of a 64 KiB message costs a count.
    """

    def __init__(self, log: PrefixLogger) -> None:
        self.counts: Counter[str] = Counter()
        self._log = log

    def drop(self, reason: str, detail: str, *args: object, log: bool = True) -> None:
        """Counts one drop and logs it when its count reaches a power of ten.

        Args:
            reason: the counter's key.
            detail: what happened, a ``%s`` template for ``args``.
            args: quoted in ``detail`` in a short form (see :func:`brief`).
            log: ``False`` counts without ever logging.
        """
        counts = self.counts
        counts[reason] += 1
        n = counts[reason]
        if log and _is_power_of_ten(n):
            text = detail % tuple(brief(arg) for arg in args) if args else detail
            if len(text) > MAX_DETAIL:
                text = f"{text[:MAX_DETAIL]}... ({len(text)} characters)"
            self._log.warning("dropped (%s, %d so far): %s", reason, n, text)


def _is_power_of_ten(n: int) -> bool:
    while n >= 10 and n % 10 == 0:
        n //= 10
    return n == 1
