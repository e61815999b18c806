"""Drops that fail a run: ``run --fail-on-drops [REASON,...]``.

The runtime drops and counts every message it refuses (a datagram that does not
decode, an inbox that is full, a duplicate, ...; see ``RunResult.protocol_errors``),
and a run goes on. A run whose robots must not drop messages says so: the run
then ends as failed when its robots dropped any for the reasons named, or for
any reason when none is named. A reason names itself and its family:
``decode`` stands for ``decode.wrong_type``, ``decode.truncated``, and the rest.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Final

from ..output._results import RunResult, RunStatus

__all__ = ["FailOnDrops"]

_REASON: Final = re.compile(r"[a-z_][a-z0-9_]*(\.[a-z0-9_]+)*")


@dataclass(frozen=True, slots=True)
class FailOnDrops:
    """The drop reasons that fail a run; none: every reason does.

    Attributes:
        reasons: drop reasons (``"queue_full"``) or families of them (``"decode"``).
    """

    reasons: frozenset[str] = frozenset()

    def __post_init__(self) -> None:
        bad = sorted(reason for reason in self.reasons if not _REASON.fullmatch(reason))
        if bad:
            raise ValueError(
                f"expected drop reasons such as decode.wrong_type or queue_full, got {bad}"
            )

    @classmethod
    def parse(cls, text: str) -> FailOnDrops:
        """``"decode,queue_full"`` as the reasons; ``""``: any reason.

        Raises:
            ValueError: a reason is not of the form of one (``queue_full``, ``decode.wrong_type``).
        """
        return cls(frozenset(part.strip() for part in text.split(",") if part.strip()))

    def fails_for(self, reason: str) -> bool:
        """Whether a drop for ``reason`` fails the run."""
        if not self.reasons:
            return True
        family = reason.partition(".")[0]
        return reason in self.reasons or family in self.reasons

    def dropped(self, counts: Mapping[str, int]) -> dict[str, int]:
        """The drops of ``counts`` (by reason) that fail the run, in reason order."""
        return {reason: n for reason, n in sorted(counts.items()) if n and self.fails_for(reason)}

    def judge(self, result: RunResult) -> bool:
        """Records the policy in ``result``; fails it if it dropped for these reasons.

        A completed, stopped or timed-out run becomes FAILED, with an error that names the
        reasons and counts; a failed run keeps its own error; an interrupted one
        stays interrupted. Returns whether drops failed the run.
        """
        result.fail_on_drops = sorted(self.reasons)
        failing = result.failing_drops = self.dropped(result.protocol_errors)
        if not failing:
            return False
        if result.status in (RunStatus.COMPLETED, RunStatus.STOPPED, RunStatus.TIMED_OUT):
            total = sum(failing.values())
            result.status = RunStatus.FAILED
            result.error = (
                f"{total:,} message{'s' if total != 1 else ''} dropped for "
                f"{_which(self.reasons)} (--fail-on-drops): {_counts(failing.items())}"
            )
        return result.status is RunStatus.FAILED


def _which(reasons: frozenset[str]) -> str:
    return "any reason" if not reasons else "reasons " + ", ".join(sorted(reasons))


def _counts(counts: Iterable[tuple[str, int]]) -> str:
    return ", ".join(f"{reason} {n:,}" for reason, n in counts)
