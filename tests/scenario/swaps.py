"""Classes a scenario's ``[layers]`` names in the layer-swap tests: good ones and bad ones.

Each bad one is refused for one reason, named after it. The one that brings a
message of its own is in :mod:`tests.scenario.swaps_messages` (a module's messages
count against every replacement defined in it).
"""

from __future__ import annotations

import abc
import dataclasses
from typing import ClassVar

from apps.fire_brigade import SoloStrategy
from apps.fire_brigade.app import FireBrigade
from apps.fire_brigade.base import Params
from apps.fire_brigade.config import FireBrigadeConfig
from apps.fire_brigade.task import Task
from cas_async import Layer
from cas_async.scenario import Mission, SimulationSetup

from .swaps_messages import SwapShout

__all__ = [
    "AbstractTask",
    "ChattyTask",
    "CountingTask",
    "DeafTask",
    "NotALayer",
    "PlainLayer",
    "SoloByLayers",
    "make_task",
    "silent",
    "stubborn",
]


class CountingTask(Task):
    """The Fire Brigade's Task, counting the instances built (so a run shows it was used)."""

    built: ClassVar[int] = 0

    def __init__(self, params: Params) -> None:
        super().__init__(params)
        type(self).built += 1


class SoloByLayers(SoloStrategy):
    """The solo strategy, under another name: put in place by ``[layers] strategy``."""


class NotALayer:
    """A class, but not a layer."""


class PlainLayer(Layer):
    """A layer, but not a Fire Brigade one (no ``BrigadeLayer``)."""


class DeafTask(Task):
    """A Task whose ``handle_msg`` takes no message: the runtime could not call it."""

    async def handle_msg(self) -> None:  # type: ignore[override]
        pass


class AbstractTask(Task, abc.ABC):
    """A Task that leaves a method to its subclasses."""

    @abc.abstractmethod
    def patience(self) -> float:
        """How long to wait for a partner."""


class ChattyTask(Task):
    """A Task whose code would send a message the stack does not have."""

    async def inner_process(self) -> None:
        """Shouts, from a nested function (the check reads nested code too)."""

        def shout() -> SwapShout:
            return SwapShout(text="here")

        self.log.debug("%r", shout())
        await super().inner_process()


def make_task(params: Params) -> Task:
    """A function, not a class."""
    return Task(params)


class _Silent(FireBrigade):
    """The Fire Brigade, without its message set: its levels can not be checked."""

    messages = None  # type: ignore[assignment]


silent = _Silent()


class _Stubborn(FireBrigade):
    """The Fire Brigade, but building its own classes whatever ``[layers]`` says."""

    def build(self, setup: SimulationSetup[FireBrigadeConfig]) -> Mission:
        return super().build(dataclasses.replace(setup, layers={}))


stubborn = _Stubborn()
