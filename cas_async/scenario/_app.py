"""The contract between the scenario runner and a simulated application.

A scenario file names its application by import path (``app = "apps.fire_brigade"``):
a module with a module-level ``app`` object that satisfies :class:`SimulationApp`.
The runner owns everything generic (loading and validating the file, the clock,
the transport, the Environment, progress, Ctrl-C, results and plots); the
application owns its own configuration sections and builds the robots.

Progress is measured through the Environment's item ledger: the application
creates, hands over and retires items from its robotic layers, and the mission
is complete when ``Mission.target`` items have been retired (delivered).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Generic, Protocol, TypeAlias, TypeVar

import numpy as np
import numpy.typing as npt

from .._clock import Clock
from .._robot import Robot
from .._supervision import RestartPolicy
from ..sim._environment import Environment
from ..transport._base import Transport

__all__ = ["Measure", "Mission", "SimulationApp", "SimulationSetup"]

Measure: TypeAlias = Callable[[Sequence[int], npt.NDArray[np.float64]], float]
"""A number the application reads off the robots' positions: ``measure(ids, xy)``.

``xy`` has shape ``(n, 2)``, row ``k`` being robot ``ids[k]``'s position. The runner
evaluates it after the run on every sample and exchange snapshot of the trace.
"""

C = TypeVar("C")
"""An application's configuration type (its ``config_type``)."""


@dataclass(frozen=True, slots=True)
class SimulationSetup(Generic[C]):
    """What the runner hands an application to build its robots with.

    Attributes:
        config: the application's configuration, an instance of ``app.config_type``.
        world: ``(width, height)`` of the area, with its corner at ``(0, 0)``.
        environment: the world every robot must be added to (with its start pose).
        clock: the clock every robot must use.
        transport: the transport every robot must use.
        rng: the run's seeded random generator; use it (or seeds drawn from it)
            for every random choice, so a seed reproduces a run.
        restart: the restart policy for every robot (``Robot(restart=...)``), from
            ``[run] restarts``; ``None``: a layer that raises fails the run.
    """

    config: C
    world: tuple[float, float]
    environment: Environment
    clock: Clock
    transport: Transport
    rng: np.random.Generator
    restart: RestartPolicy | None = None


@dataclass(slots=True)
class Mission:
    """The robots an application built, and what counts as done.

    Attributes:
        robots: every robot, each already added to the Environment.
        target: items to retire for the mission to be complete.
        groups: robot ids by label, in the order to show them (e.g. ``"Generator"``).
        extra: returns application-specific figures for the results; called once,
            at the end of the run.
        measures: named :data:`Measure` functions of the robots' positions. Each
            is reported over time and by exchange count (results.json ``series`` and
            ``by_exchange``), and as one number, its mean over the last third of the
            run (``metrics``, the summary table, sweeps).
        snapshot_exchanges: exchange counts the figures show robots at, where the
            run reached them (e.g. the counts of a paper's figures); empty: six
            counts spread over the run.
    """

    robots: Sequence[Robot]
    target: int
    groups: dict[str, list[int]] = field(default_factory=dict)
    extra: Callable[[], dict[str, float | int | str]] | None = None
    measures: Mapping[str, Measure] = field(default_factory=dict)
    snapshot_exchanges: Sequence[int] = ()


class SimulationApp(Protocol[C]):
    """An application the scenario runner can run (see the module docs).

    Attributes:
        name: shown in the summary, e.g. ``"Fire Brigade"``.
        item_name: what its items are, singular, e.g. ``"bucket"``.
        config_type: a frozen dataclass: the scenario file's keys other than
            ``app``, ``run`` and ``world`` are validated into it.
    """

    name: str
    item_name: str
    config_type: type[C]

    def robots(self, config: C) -> Mapping[str, int]:
        """How many robots ``config`` builds, by the key that sets each number.

        Computed without building anything: the loader checks the total against
        the machine's memory (and sockets, on UDP) before :meth:`check` and
        :meth:`build` run, and names the key with the most robots when it is too
        many. ``{"transporters.count": 16, "stations": 4}``, say.
        """

    def check(self, config: C, world: tuple[float, float]) -> None:
        """Checks what needs several keys at once (robots inside the world, …).

        Raises:
            ScenarioError: naming the key at fault.
        """

    def build(self, setup: SimulationSetup[C]) -> Mission:
        """Creates the robots, adds them to ``setup.environment``, returns the mission."""
