"""The contract between the scenario runner and a simulated application.

A scenario file names its application by import path (``app = "apps.fire_brigade"``):
a module with a module-level ``app`` object that satisfies :class:`SimulationApp`.
The runner owns everything generic (loading and validating the file, the clock,
the transport, the Environment, progress, Ctrl-C, results and plots); the
application owns its own configuration sections and builds the robots.

What a mission is for is its :class:`~cas_async.scenario.Objective`: when it is
done, what the progress line shows, what is checked at every sample and what the
results hold. The ready-made one, :class:`~cas_async.scenario.Items`, counts the
Environment's items: the application creates, hands over and retires them from
its robotic layers, and the mission is complete when ``target`` items have been
retired (delivered). A mission that only gives ``Mission(robots, target)`` gets it.

An application may name the levels of its stack (``stack``: one
:class:`LayerSlot` per level, top first). A scenario file can then replace any of
them by a class of its own (``[layers] coordination = "my_package.MyCoordination"``),
which the loader checks before anything starts, and the app builds each level
with ``setup.layer(SLOT)``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Final, Generic, Protocol, TypeAlias, TypeVar, cast

import numpy as np
import numpy.typing as npt

from ..._core._channel import DEFAULT_QUEUE_LIMIT
from ..._core._layer import Layer
from ..._core._robot import Robot
from ..._core._supervision import RestartPolicy
from ..._core._transport_contract import Transport
from ..._errors import ConfigurationError
from ..._time._clock import Clock
from ..._types import RobotId
from ..._wire._codec import DEFAULT_MAX_DATAGRAM
from ..._wire._message import Message
from ...sim._environment import Environment
from ._objective import Items, Objective
from ._scene import Scene

__all__ = [
    "APP_MEMBERS",
    "LayerSlot",
    "Measure",
    "Mission",
    "SimulationApp",
    "SimulationSetup",
    "app_problems",
]

Measure: TypeAlias = Callable[[Sequence[int], npt.NDArray[np.float64]], float]
"""A number the application reads off the robots' positions: ``measure(ids, xy)``.

``xy`` has shape ``(n, 2)``, row ``k`` being robot ``ids[k]``'s position. The runner
evaluates it after the run on every sample and exchange snapshot of the trace.
"""

C = TypeVar("C")
"""An application's configuration type (its ``config_type``)."""
L = TypeVar("L", bound=Layer)


@dataclass(frozen=True, slots=True)
class LayerSlot(Generic[L]):
    """One level of an application's stack, by name: what a scenario's ``[layers]`` may replace.

    Attributes:
        name: the level's key in ``[layers]`` (``"coordination"``); its index in
            the stack (``2``) names it too.
        base: the class a replacement must subclass: the application builds the
            level as it builds ``base`` (same constructor, same role).
        default: the class built when the scenario replaces nothing.
    """

    name: str
    base: type[L]
    default: type[L]

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"LayerSlot: name must be an identifier, got {self.name!r}")
        if not issubclass(self.default, self.base):
            raise ValueError(
                f"LayerSlot {self.name!r}: default {self.default.__qualname__} "
                f"is not a subclass of base {self.base.__qualname__}"
            )


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
        layers: the classes the scenario's ``[layers]`` put in place of the
            app's own, by slot name (checked: each subclasses its slot's base);
            read them with :meth:`layer`.
        share: the robots this process runs, when it runs only some (a worker of a
            run across processes; none for the world); ``None``: every robot. Ask
            with :meth:`holds`.
    """

    config: C
    world: tuple[float, float]
    environment: Environment
    clock: Clock
    transport: Transport
    rng: np.random.Generator
    restart: RestartPolicy | None = None
    layers: Mapping[str, type[Layer]] = field(default_factory=dict)
    share: frozenset[RobotId] | None = None

    def holds(self, robot_id: RobotId) -> bool:
        """Whether this process runs robot ``robot_id``: build its layers and robot only then.

        Across processes each worker runs a share of the robots, and the world none.
        An app builds every robot's place and draws every random number for every
        robot, in the same order, held or not (add it to :attr:`environment`, draw its
        seed), and skips only what draws nothing: its layers, its middleware, its
        :class:`~cas_async.Robot`. A worker then holds only its own robots, and the
        world none. An app that never asks builds every robot everywhere, as before:
        correct, slower. In one process every robot is held.
        """
        return self.share is None or robot_id in self.share

    def layer(self, slot: LayerSlot[L], default: type[L] | None = None) -> type[L]:
        """The class to build ``slot``'s level with: the scenario's, else ``default`` or the slot's.

        ``default`` is for an app whose own choice depends on its configuration
        (the Fire Brigade's ``strategy.name``); a scenario's ``[layers]`` wins over it.
        """
        chosen = self.layers.get(slot.name)
        if chosen is not None:
            return cast(type[L], chosen)  # the loader checked it subclasses slot.base
        return slot.default if default is None else default

    def robot(
        self,
        robot_id: RobotId,
        layers: Sequence[Layer],
        *,
        messages: Iterable[type[Message]] | None = None,
        max_datagram_size: int = DEFAULT_MAX_DATAGRAM,
        queue_limit: int = DEFAULT_QUEUE_LIMIT,
        reply_memory: float = 60.0,
    ) -> Robot:
        """A :class:`~cas_async.Robot` on this run's transport and clock, with its restart policy.

        ``setup.robot(7, layers, messages=MESSAGES)`` is
        ``Robot(7, layers, transport=setup.transport, clock=setup.clock,
        messages=MESSAGES, restart=setup.restart)``; the other arguments are
        :class:`~cas_async.Robot`'s. Add the robot to :attr:`environment` as well
        (``environment.add_robot(robot_id, pose)``): where it stands is the app's.
        """
        return Robot(
            robot_id,
            layers,
            transport=self.transport,
            clock=self.clock,
            messages=messages,
            max_datagram_size=max_datagram_size,
            queue_limit=queue_limit,
            restart=self.restart,
            reply_memory=reply_memory,
        )


@dataclass(slots=True)
class Mission:
    """The robots an application built, and what counts as done.

    Give either ``target`` (the mission retires that many items: :class:`Items`)
    or an ``objective`` of the application's own.

    Attributes:
        robots: every robot, each already added to the Environment.
        target: items to retire for the mission to be complete (an item mission).
        groups: robot ids by label, in the order to show them (e.g. ``"Generator"``).
        extra: returns application-specific figures for the results, by name, each
            a number, a ``str`` or a ``bool`` (see ``RunResult.extra``); called
            once, at the end of the run.
        measures: named :data:`Measure` functions of the robots' positions. Each
            is reported over time and by exchange count (results.json ``series`` and
            ``by_exchange``), and as one number, its mean over the last third of the
            run (``metrics``, the summary table, sweeps).
        snapshot_exchanges: exchange counts the figures show robots at, where the
            run reached them (e.g. the counts of a paper's figures); empty: six
            counts spread over the run.
        objective: what the mission is for, when it is not retiring ``target``
            items: its end, its progress, its checks and its results.
        scene: what the world holds besides the robots (zones, stations, objects):
            the live view, the replay and the MCAP export draw it.

    Raises:
        ValueError: neither or both of ``target`` and ``objective`` were given.
    """

    robots: Sequence[Robot]
    target: int | None = None
    groups: dict[str, list[int]] = field(default_factory=dict)
    extra: Callable[[], dict[str, float | int | str]] | None = None
    measures: Mapping[str, Measure] = field(default_factory=dict)
    snapshot_exchanges: Sequence[int] = ()
    objective: Objective | None = None
    scene: Scene = field(default_factory=Scene)

    def __post_init__(self) -> None:
        if (self.target is None) == (self.objective is None):
            raise ValueError(
                "Mission: give target (items to retire) or an objective, "
                f"not {'both' if self.objective is not None else 'neither'}"
            )


class SimulationApp(Protocol[C]):
    """What a scenario's ``app = "package.module"`` names: an application the runner can run.

    The loader imports the module and takes its ``app`` (or the attribute after a
    colon, ``"package.module:my_app"``). It must have the five members below; a
    missing one is reported as ``app "package.module" lacks robots(config): ...``
    before anything runs. Annotating it, ``app: SimulationApp[MyConfig] = MyApp()``,
    has mypy check the contract.

    Three more attributes are read when present (:data:`APP_MEMBERS` lists all eight):

    * ``item_name: str``: what the items of a ``Mission(robots, target)`` are,
      singular (``"bucket"``; default ``"item"``);
    * ``stack: Sequence[LayerSlot]``: every level of the robots' stack, top first,
      so that a scenario's ``[layers]`` may replace any of them (the robots must
      have exactly these levels; build each with ``setup.layer(SLOT)``);
    * ``messages: Sequence[type[Message]]``: the stack's message classes (needed
      with ``stack``): a replacement layer may not add to them.

    Attributes:
        name: shown in the summary and results, e.g. ``"Fire Brigade"``.
        config_type: a dataclass (frozen, keys declared with
            :func:`~cas_async.scenario.setting`): the scenario file's keys other than
            ``app``, ``run``, ``world``, ``faults`` and ``layers`` are validated into
            it, and the other members get an instance of it.
    """

    name: str
    config_type: type[C]

    def robots(self, config: C) -> Mapping[str, int]:
        """How many robots ``config`` builds, by the key that sets each number.

        Computed without building anything: the loader checks the total against
        the machine's memory (and sockets, on UDP) before :meth:`check` and
        :meth:`build` run, and names the key with the most robots when it is too
        many (``count = 1000000000000`` fails at once instead of filling memory).
        ``{"transporters.count": 16, "stations": 4}``, say.
        """

    def check(self, config: C, world: tuple[float, float]) -> None:
        """Checks what needs several keys at once (robots inside the world, …).

        Each key's own type and bounds are checked already (from ``config_type``);
        an app with nothing more to check does nothing here.

        Raises:
            ScenarioError: naming the key at fault: ``ScenarioError([(key, problem)])``.
        """

    def build(self, setup: SimulationSetup[C]) -> Mission:
        """Creates the robots, adds them to ``setup.environment``, returns the mission."""


APP_MEMBERS: Final[Mapping[str, tuple[bool, str]]] = {
    "name": (True, "name: str, the app's name in the summary"),
    "config_type": (
        True,
        "config_type: the dataclass the scenario's own keys are validated into",
    ),
    "robots": (
        True,
        "robots(config) -> Mapping[str, int]: how many robots a configuration builds, by "
        "the key that sets each number, so that the loader checks this machine holds them "
        "before anything is built",
    ),
    "check": (
        True,
        "check(config, world) -> None: checks across keys, raising "
        "ScenarioError([(key, problem)]) (an app with nothing to check returns None)",
    ),
    "build": (
        True,
        "build(setup: SimulationSetup) -> Mission: builds the robots, adds them to "
        "setup.environment and says what the mission is for",
    ),
    "item_name": (False, "item_name: str, what a target's items are (default 'item')"),
    "stack": (False, "stack: Sequence[LayerSlot], the stack's levels, top first"),
    "messages": (False, "messages: Sequence[type[Message]], the stack's message classes"),
}
"""Every member of :class:`SimulationApp`, by name: ``(required, what it is)``."""

_CALLED: Final = frozenset({"robots", "check", "build"})


def app_problems(app: object) -> list[str]:
    """What ``app`` lacks to be a :class:`SimulationApp`, one text per member.

    A required member that is missing (``"lacks robots(config) -> Mapping[str, int]:
    how many robots ..."``), a method that is not callable, a ``name`` or
    ``item_name`` that is not text. Empty when nothing is wrong.
    """
    problems: list[str] = []
    for member, (required, what) in APP_MEMBERS.items():
        value = getattr(app, member, None)
        if value is None:
            if required:
                problems.append(f"lacks {what}")
        elif member in _CALLED and not callable(value):
            problems.append(f"has {member} = {value!r}, which is not a method; expected {what}")
        elif member in ("name", "item_name") and not isinstance(value, str):
            problems.append(f"has {member} = {value!r}, which is not text; expected {what}")
    return problems


def objective_of(mission: Mission, app_name: str, item_name: str) -> Objective:
    """The mission's objective: its own, or retiring its ``target`` items.

    Raises:
        ConfigurationError: the mission has neither.
    """
    if mission.objective is not None:
        return mission.objective
    if mission.target is None:  # Mission refuses neither, but it is not frozen
        raise ConfigurationError(f"{app_name}: the mission has no target nor objective")
    return Items(mission.target, item_name)
