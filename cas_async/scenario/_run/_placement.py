"""Where a run's robots run, and how the run follows them: one object per mode.

:class:`~cas_async.scenario.ScenarioRun` is the same for every run: it builds the
mission, watches its objective, samples what it observes and measures it. Where
the robots run, and so how time moves and what the run observes, is a
:class:`Placement`, chosen once by :func:`place`:

- :class:`Sampled`: the robots run here; the run samples their Environment every
  ``trace_interval`` simulated seconds (scaled time, or virtual time without a
  network latency);
- :class:`Windowed`: the robots run here, on virtual time with a latency: time
  moves in windows and the run observes a mirror fed window by window (see
  :mod:`._windowed`), as a run across processes does;
- :class:`WorkersWindowed` and :class:`WorkersFollowed`: the robots run in a
  world's workers (``run --processes``, see :mod:`._world`), on virtual time in
  windows the world grants, or on scaled time as their reports come; the run
  observes a mirror of them.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable, Coroutine
from dataclasses import dataclass
from typing import Any, Protocol, final

from ..._core._swarm import Swarm
from ..._errors import ConfigurationError, LayerError
from ..._time._clock import Clock
from ..._time._virtual_loop import VirtualTimeLoop
from ..._wire._swarm_key import SwarmKey
from ...sim._environment import Environment
from ...transport import Transport
from .._processes._observer import Observer, mirror_of
from .._processes._windows import Held
from .._processes._world import World
from .._spec._app import Mission
from .._spec._loader import Scenario
from .._spec._objective import Objective, not_distributable
from .._spec._run_transport import fault_counts, run_transport
from ..output._results import RunStatus
from ._sampled import sampled_until_end
from ._windowed import WindowedRun

__all__ = ["Placement", "Sampling", "place", "transport_for"]

Ended = tuple[RunStatus, BaseException | None]
"""How a run ended, and the failure of a failed one."""
Counts = tuple[dict[str, dict[str, int]], dict[str, int]]
"""Messages by kind and class, and drops by reason."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Sampling:
    """What the run does at each sample instant, for the placement to call."""

    clock: Clock
    max_time: float
    interval: float
    """Simulated seconds between two samples (``run.trace_interval``)."""
    sample: Callable[[float], None]
    """Takes the sample at an instant."""
    hold: Callable[[float], Coroutine[Any, Any, None]]
    """Awaited after each sample: what the run's listeners hold it for (a paced view)."""
    sample_held: Callable[[float], Awaitable[None]]
    """``sample`` then ``hold``: for an observer that samples a mirror."""
    behind: Callable[[float], None]
    """Told how far after its instant a sample came (scaled time)."""
    done: Callable[[], bool]
    """Whether the mission is complete."""

    def until_end(
        self, running: Coroutine[Any, Any, None], complete: asyncio.Event, stop: asyncio.Event
    ) -> Coroutine[Any, Any, Ended]:
        """Samples while ``running`` runs, until an end (see :func:`.sampled_until_end`)."""
        return sampled_until_end(
            running, self.clock, self.max_time, self.interval, complete, stop,
            self.sample, self.hold, self.behind,
        )  # fmt: skip


class Placement(Protocol):
    """Where the robots of one run run (see the module docs)."""

    @property
    def environment(self) -> Environment:
        """What the run observes: the robots' Environment, or a mirror of it."""

    @property
    def swarm(self) -> Swarm:
        """The robots that run in this process (none when workers run them)."""

    def arm(self) -> None:
        """Before the robots start, on the run's loop: time moves as this mode needs."""

    async def start(self) -> None:
        """Starts the robots."""

    async def until_done(self, complete: asyncio.Event, stop: asyncio.Event) -> Ended:
        """Runs until an end: the mission ``complete``, ``max_time``, ``stop``, a failure."""

    def abandon(self) -> None:
        """The run ends at once (a signal): whatever runs elsewhere is stopped now."""

    def ended(self, status: RunStatus) -> None:
        """The run ended with ``status``: observed up to where it stands, time freed."""

    def observed_until(self) -> float | None:
        """The instant the run was observed up to, when it is observed window by window."""

    def decided(self) -> RunStatus | None:
        """Completed or stopped, once known, if the robots run on before the run ends."""

    def stats(self) -> dict[str, float | int | str]:
        """What this mode adds to the results' ``extra``."""

    def message_counts(self) -> Counts:
        """Messages by kind and class, and drops by reason, of every robot of the run."""

    def fault_counts(self) -> dict[str, int] | None:
        """What the ``[faults]`` did on the robots' wires (``None``: no faults)."""

    async def stop(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: object
    ) -> None:
        """Stops the robots it started (a layer's failure found meanwhile is raised)."""

    async def close(self, *, hurry: bool) -> None:
        """Closes what the mode opened, whether the robots started or not."""


def transport_for(
    scenario: Scenario,
    clock: Clock,
    key: SwarmKey | None,
    world: World | None,
    environment: Environment,
) -> Transport:
    """What the application builds its robots with: the run's, or copies a world never starts."""
    if world is not None:
        return world.transport()
    return run_transport(scenario, clock, key, environment)


def place(
    scenario: Scenario,
    environment: Environment,
    transport: Transport,
    mission: Mission,
    objective: Objective,
    sampling: Sampling,
    world: World | None,
) -> Placement:
    """The placement of a built mission: in the ``world``'s workers when given, else here.

    Raises:
        ConfigurationError: workers cannot run the mission (its objective keeps its
            state in one process, or the partition is wrong).
    """
    if world is not None:
        if not objective.distributable:
            raise ConfigurationError(not_distributable(scenario.path, scenario.app.name, objective))
        world.adopt(environment, mission)
        if scenario.run.virtual:
            return WorkersWindowed(world, mirror_of(environment), sampling)
        return WorkersFollowed(world, mirror_of(environment), sampling)
    swarm = Swarm(mission.robots)
    # An objective that reads the Environment only (distributable) may read a mirror.
    if scenario.run.virtual and scenario.network.latency > 0 and objective.distributable:
        windowed = WindowedRun(scenario, environment, sampling.clock, sampling.sample_held,
                               sampling.done)  # fmt: skip
        return Windowed(swarm, transport, windowed)
    return Sampled(swarm, transport, environment, sampling)


class _Here:
    """The robots run in this process, on ``transport``."""

    def __init__(self, swarm: Swarm, transport: Transport) -> None:
        self._swarm = swarm
        self._transport = transport

    @property
    def swarm(self) -> Swarm:
        return self._swarm

    async def start(self) -> None:
        await self._swarm.__aenter__()

    def abandon(self) -> None:
        """Nothing runs elsewhere: the robots stop when the run's block is left."""

    def message_counts(self) -> Counts:
        return self._swarm.message_counts(), self._swarm.drop_counts()

    def fault_counts(self) -> dict[str, int] | None:
        return fault_counts(self._transport)

    async def stop(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: object
    ) -> None:
        await self._swarm.__aexit__(exc_type, exc, tb)


@final
class Sampled(_Here):
    """The robots run here; their own Environment is sampled (see the module docs)."""

    def __init__(
        self, swarm: Swarm, transport: Transport, environment: Environment, sampling: Sampling
    ) -> None:
        super().__init__(swarm, transport)
        self._environment = environment
        self._sampling = sampling

    @property
    def environment(self) -> Environment:
        return self._environment

    def arm(self) -> None:
        """Time moves freely."""

    async def until_done(self, complete: asyncio.Event, stop: asyncio.Event) -> Ended:
        return await self._sampling.until_end(self._swarm.run(), complete, stop)

    def ended(self, status: RunStatus) -> None:
        """Sampled up to the end already."""

    def observed_until(self) -> float | None:
        return None

    def decided(self) -> RunStatus | None:
        return None  # it ends as soon as it is decided

    def stats(self) -> dict[str, float | int | str]:
        return {}

    async def close(self, *, hurry: bool) -> None:
        """Nothing of its own to close."""


@final
class Windowed(_Here):
    """The robots run here in windows; a mirror of them is observed (see the module docs)."""

    def __init__(self, swarm: Swarm, transport: Transport, windowed: WindowedRun) -> None:
        super().__init__(swarm, transport)
        self._windowed = windowed

    @property
    def environment(self) -> Environment:
        return self._windowed.mirror

    def arm(self) -> None:
        self._windowed.start()  # before any robot's first instant

    async def until_done(self, complete: asyncio.Event, stop: asyncio.Event) -> Ended:
        return await self._windowed.until_done(self._swarm.run(), complete, stop)

    def ended(self, status: RunStatus) -> None:
        if status in (RunStatus.INTERRUPTED, RunStatus.FAILED):
            self._windowed.observe_now()  # between two windows: measured where it stands
        self._windowed.stop()

    def observed_until(self) -> float | None:
        return self._windowed.observed_until

    def decided(self) -> RunStatus | None:
        return self._windowed.verdict

    def stats(self) -> dict[str, float | int | str]:
        return {"windows": self._windowed.rounds}

    async def close(self, *, hurry: bool) -> None:
        self._windowed.stop()  # a start that failed left its windows on the loop


class _InWorkers:
    """The robots run in a world's workers; the run observes ``mirror``, fed by the world."""

    def __init__(self, world: World, mirror: Environment, sampling: Sampling) -> None:
        self._world = world
        self._mirror = mirror
        self._sampling = sampling
        self._observer = Observer(mirror, sampling.interval, sampling.sample_held, sampling.done)
        self._swarm = Swarm(())

    @property
    def environment(self) -> Environment:
        return self._mirror

    @property
    def swarm(self) -> Swarm:
        return self._swarm

    async def start(self) -> None:
        await self._world.start(self._sampling.clock)

    async def _finished(self, running: Awaitable[Ended], stop: asyncio.Event) -> Ended:
        """Until ``running`` ends the run; then the workers stop and send their last counts."""
        try:
            ended = await running
        except LayerError as error:
            ended = RunStatus.FAILED, error
        await self._world.finish(hurry=stop.is_set())
        return ended

    def abandon(self) -> None:
        self._world.abandon()

    def ended(self, status: RunStatus) -> None:
        """The world observed what its workers reported."""

    def decided(self) -> RunStatus | None:
        return None  # the world decides and ends the run in one step

    def stats(self) -> dict[str, float | int | str]:
        return self._world.stats()

    def message_counts(self) -> Counts:
        return self._world.message_counts()

    def fault_counts(self) -> dict[str, int] | None:
        return self._world.fault_counts()  # the robots' wires are the workers'

    async def stop(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: object
    ) -> None:
        """The workers stop their robots when the world tells them (:meth:`until_done`)."""

    async def close(self, *, hurry: bool) -> None:
        await self._world.close(hurry=hurry)


@final
class WorkersWindowed(_InWorkers):
    """Virtual time: the world grants the workers windows and observes each."""

    def arm(self) -> None:
        loop = asyncio.get_running_loop()
        if isinstance(loop, VirtualTimeLoop):  # no robots here: time stands still
            loop.run_windows(Held(self._world.tick))

    async def until_done(self, complete: asyncio.Event, stop: asyncio.Event) -> Ended:
        coordinated = self._world.coordinate(self._observer, complete.is_set, stop)
        return await self._finished(coordinated, stop)

    def observed_until(self) -> float | None:
        return self._observer.until


@final
class WorkersFollowed(_InWorkers):
    """Scaled time: the workers report as they go; the run samples the mirror as it follows."""

    def arm(self) -> None:
        """Time is the wall clock's."""

    async def until_done(self, complete: asyncio.Event, stop: asyncio.Event) -> Ended:
        followed = self._sampling.until_end(self._world.follow(self._observer), complete, stop)
        return await self._finished(followed, stop)

    def observed_until(self) -> float | None:
        return None
