"""A toy application for the sweep tests: the chores of ``objective_apps``, with trouble on demand.

``[trouble] mode`` says what its build does first: ``"none"``, ``"sleep"`` (for
``seconds`` of wall time: a run long enough to stop a sweep in the middle of,
that costs no CPU), ``"raise"`` (a ``RuntimeError``), ``"exit"`` (``sys.exit(3)``)
or ``"die"`` (``os._exit(3)``: its worker process ends). A run takes about 20 ms
plus its sleep. :func:`scenario` writes a scenario file for it.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from cas_async.scenario import Mission, SimulationSetup, setting
from tests.scenario.objective_apps import Chores, ChoresApp

__all__ = ["Trouble", "TroubleApp", "TroubleConfig", "app", "scenario"]


@dataclass(frozen=True)
class Trouble:
    """The ``[trouble]`` table."""

    mode: Literal["none", "sleep", "raise", "exit", "die"] = setting(
        "none", doc="what the build does first"
    )
    seconds: float = setting(0.0, ge=0, doc="wall seconds of a sleep")


@dataclass(frozen=True)
class TroubleConfig:
    chores: Chores = setting(default_factory=Chores)
    trouble: Trouble = setting(default_factory=Trouble)


class TroubleApp(ChoresApp):
    name = "Trouble"
    config_type = TroubleConfig  # type: ignore[assignment]

    def build(self, setup: SimulationSetup[TroubleConfig]) -> Mission:  # type: ignore[override]
        trouble = setup.config.trouble
        if trouble.mode == "sleep":
            time.sleep(trouble.seconds)
        elif trouble.mode == "raise":
            raise RuntimeError("the build broke on purpose")
        elif trouble.mode == "exit":
            sys.exit(3)
        elif trouble.mode == "die":
            os._exit(3)
        return super().build(setup)  # type: ignore[arg-type]


app = TroubleApp()


def scenario(folder: Path, *lines: str) -> Path:
    """Writes ``folder/trouble.toml`` (with ``lines`` added) and returns its path."""
    path = folder / "trouble.toml"
    text = "\n".join(['app = "tests.scenario.sweep_apps"', "[world]", "width = 10", "height = 10"])
    path.write_text("\n".join([text, *lines]) + "\n", encoding="utf-8")
    return path
