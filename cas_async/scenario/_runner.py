"""Running a loaded scenario: clock, transport, Environment, the app's swarm, and measuring it.

``run_scenario`` is the whole run as one coroutine, so it can be embedded in any
asyncio program; the CLI only adds argument parsing, signals and output files.
The run ends when the app's target number of items has been retired, when
``run.max_time`` simulated seconds have passed, when ``stop`` is set (Ctrl-C), or
when a layer fails; in every case the result says which, and holds what was
measured up to then.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
import traceback
from collections.abc import Callable
from typing import Any, TextIO

import numpy as np

from .._clock import Clock, ScaledClock, VirtualClock
from .._errors import ConfigurationError, LayerError
from .._swarm import Swarm
from .._swarm_key import SwarmKey
from ..sim._environment import Environment
from ..sim._items import ItemEvent, ItemEventKind
from ..transport._authenticated import AuthenticatedTransport
from ..transport._base import Transport
from ..transport._faulty import FaultyTransport
from ..transport._memory import MemoryTransport
from ..transport._udp import UdpTransport
from ._app import Mission, SimulationSetup
from ._gc_policy import young_generation_for
from ._loader import Scenario
from ._progress import Progress
from ._results import RunResult, RunStatus
from ._trace import Trace

__all__ = ["check_key", "run_scenario"]


def check_key(scenario: Scenario, key: SwarmKey | None) -> None:
    """Raises ``ConfigurationError`` when ``scenario`` cannot run signed with ``key``."""
    if scenario.run.pass_objects and key is not None:
        raise ConfigurationError(
            f"{scenario.path}: run.pass_objects passes message objects, which a swarm key cannot "
            "sign; set run.pass_objects = false to run with a key"
        )


def _transport(scenario: Scenario, clock: Clock, key: SwarmKey | None) -> Transport:
    """The run's transport: the ``[faults]`` on the wire, if any, and signed with ``key``."""
    run = scenario.run
    check_key(scenario, key)
    transport: Transport = (
        MemoryTransport(pass_objects=run.pass_objects)
        if run.transport == "memory"
        else UdpTransport()
    )
    faults = scenario.faults.as_faults()
    if faults.any:
        seed = run.seed if scenario.faults.seed is None else scenario.faults.seed
        transport = FaultyTransport(transport, faults, seed=seed, clock=clock)
    return transport if key is None else AuthenticatedTransport(transport, key)


def _clock(scenario: Scenario) -> Clock:
    run = scenario.run
    return VirtualClock() if run.virtual else ScaledClock(run.time_factor)


async def run_scenario(
    scenario: Scenario,
    *,
    progress_to: TextIO | None = None,
    stop: asyncio.Event | None = None,
    observe: Callable[[Environment], None] | None = None,
    wall_clock: Callable[[], float] = time.perf_counter,
    key: SwarmKey | None = None,
) -> tuple[RunResult, Trace]:
    """Runs ``scenario`` to its end and returns what it measured and the position trace.

    Run it on the loop the scenario needs: ``cas_async.run(run_scenario(s),
    virtual=s.run.virtual)``. While the swarm runs, the garbage collector's
    youngest generation is sized to the swarm (see :mod:`.gc_policy`): the
    process-wide threshold is raised for thousands of robots, then restored.

    Args:
        scenario: a loaded, validated scenario.
        progress_to: where to show progress while running (simulated time, items
            delivered, exchanges): a live line on a terminal, plain lines otherwise.
        stop: when set, the run stops early with status INTERRUPTED.
        observe: called with the Environment once the robots are in it, before they
            start (a test can subscribe to ``environment.items`` there, for instance).
        wall_clock: measures the wall time.
        key: the swarm key: every datagram is signed and checked (see
            :class:`~cas_async.transport._authenticated.AuthenticatedTransport`).
    """
    started = wall_clock()
    run = scenario.run
    world = (scenario.world.width, scenario.world.height)
    environment = Environment()
    clock = _clock(scenario)
    transport = _transport(scenario, clock, key)
    setup: SimulationSetup[Any] = SimulationSetup(
        scenario.config,
        world,
        environment,
        clock,
        transport,
        np.random.default_rng(run.seed),
        run.restart,
    )
    mission = scenario.app.build(setup)
    progress = None
    if progress_to is not None:
        progress = Progress(
            progress_to,
            target=mission.target,
            item_name=scenario.app.item_name,
            interval=run.progress_interval,
        )
    result = RunResult(
        scenario=str(scenario.path),
        app=scenario.app.name,
        item_name=scenario.app.item_name,
        seed=run.seed,
        target=mission.target,
        groups={label: list(ids) for label, ids in mission.groups.items()},
        config=scenario.data,
    )
    trace = Trace(environment.robot_ids)
    ledger = environment.items
    complete = asyncio.Event()

    def on_item(event: ItemEvent) -> None:
        if event.kind is ItemEventKind.TRANSFERRED:
            if run.trace_exchanges:
                trace.exchange(event.t, ledger.transfers, environment.positions_at(event.t).xy)
        elif event.kind is ItemEventKind.RETIRED and ledger.retired == mission.target:
            result.makespan = event.t
            complete.set()
        if progress is not None:
            progress.update(event.t, ledger.retired, ledger.transfers)

    ledger.subscribe(on_item)
    if observe is not None:
        observe(environment)
    swarm = Swarm(mission.robots)
    try:
        with young_generation_for(len(mission.robots)):
            async with swarm:
                result.status, failure = await _until_done(
                    swarm,
                    clock,
                    run.max_time,
                    run.trace_interval,
                    complete,
                    stop,
                    lambda t: _sample(
                        t, environment, trace, progress, ledger.retired, ledger.transfers
                    ),
                )
        if failure is not None:
            _failed(result, failure)
    except LayerError as exc:  # raised again on the way out when a layer failed
        _failed(result, exc)
    except BaseException:
        if progress is not None:
            progress.close(final=False)  # whatever is printed next starts on a fresh line
        raise
    _measure(result, mission, swarm, environment, clock.now())
    wire = transport.inner if isinstance(transport, AuthenticatedTransport) else transport
    if isinstance(wire, FaultyTransport):  # read after the swarm closed its endpoints
        result.faults = wire.stats
    result.wall_time = wall_clock() - started
    if progress is not None:
        progress.close(final=True)
    return result, trace


def _sample(
    t: float,
    environment: Environment,
    trace: Trace,
    progress: Progress | None,
    delivered: int,
    exchanges: int,
) -> None:
    # Every hand-over already checks the items it touches; this is the full audit.
    environment.items.check()
    trace.sample(t, environment.positions_at(t).xy)
    if progress is not None:
        progress.update(t, delivered, exchanges)


async def _until_done(
    swarm: Swarm,
    clock: Clock,
    max_time: float,
    interval: float,
    complete: asyncio.Event,
    stop: asyncio.Event | None,
    sample: Callable[[float], None],
) -> tuple[RunStatus, BaseException | None]:
    """Samples every ``interval`` simulated seconds until one of the ends; returns which.

    The exception is that of a failed run (a layer's, or the sampling's).
    """

    async def sampling() -> None:
        tick = 0
        while True:
            # Absolute instants: no drift however late each wake-up is.
            t = tick * interval
            await clock.sleep_until(t)
            sample(clock.now())
            tick += 1

    waits = {
        "complete": asyncio.ensure_future(complete.wait()),
        "timeout": asyncio.ensure_future(clock.sleep_until(max_time)),
        "swarm": asyncio.ensure_future(swarm.run()),
        "sampling": asyncio.ensure_future(sampling()),
    }
    if stop is not None:
        waits["stop"] = asyncio.ensure_future(stop.wait())
    try:
        done, _ = await asyncio.wait(waits.values(), return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in waits.values():
            task.cancel()
        for task in waits.values():
            with contextlib.suppress(asyncio.CancelledError):
                await task
    if waits["complete"] in done:
        return RunStatus.COMPLETED, None
    if waits["swarm"] in done or waits["sampling"] in done:
        error = (waits["swarm"] if waits["swarm"] in done else waits["sampling"]).exception()
        return RunStatus.FAILED, error or RuntimeError("the swarm stopped")
    if "stop" in waits and waits["stop"] in done:
        return RunStatus.INTERRUPTED, None
    return RunStatus.TIMED_OUT, None


def _failed(result: RunResult, error: BaseException) -> None:
    """Marks the run failed, with the error and the traceback of what raised."""
    result.status, result.error = RunStatus.FAILED, str(error)
    cause = error.__cause__ or error
    result.traceback = "".join(traceback.format_exception(cause)).rstrip()


def _measure(
    result: RunResult, mission: Mission, swarm: Swarm, environment: Environment, now: float
) -> None:
    ledger = environment.items
    result.sim_time = now
    result.created, result.delivered, result.exchanges = (
        ledger.created,
        ledger.retired,
        ledger.transfers,
    )
    for event in ledger.events:
        if event.kind is ItemEventKind.RETIRED:
            history = ledger.history(event.item)
            result.travel_times.append(event.t - history[0].t)
            result.handovers_per_item.append(
                sum(e.kind is ItemEventKind.TRANSFERRED for e in history)
            )
    result.distance = {
        robot_id: travelled
        for robot_id, travelled in environment.distances(now).items()
        if environment.is_mobile(robot_id)
    }
    counts = swarm.message_counts()
    result.messages_internal = dict(sorted(counts["internal"].items()))
    result.messages_external = dict(sorted(counts["external"].items()))
    errors: dict[str, int] = {}
    for robot in swarm:
        for reason, n in robot.dropped.items():
            errors[reason] = errors.get(reason, 0) + n
    result.protocol_errors = dict(sorted(errors.items()))
    if mission.extra is not None:
        result.extra = dict(mission.extra())
