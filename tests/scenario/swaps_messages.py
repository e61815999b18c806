"""A replacement layer whose module defines a message the Fire Brigade's stack does not have.

``[layers] task = "tests.scenario.swaps_messages.LoudTask"`` must be refused: the
robots would no longer agree on the message set.
"""

from __future__ import annotations

from apps.fire_brigade.task import Task
from cas_async import Message, message

__all__ = ["LoudTask", "SwapShout"]


@message
class SwapShout(Message):
    """A message no Fire Brigade robot knows."""

    text: str = ""


class LoudTask(Task):
    """The Fire Brigade's Task, in a module that brings :class:`SwapShout` along."""
