"""A scenario file end to end: read, override, import the app, validate, check.

A scenario is a TOML file::

    app = "apps.fire_brigade"   # import path: "package.module" or "package.module:attr"

    [run]                       # optional: how to run it (RunConfig)
    seed = 7
    virtual = true

    [world]                     # required: the area (WorldConfig)
    width = 200.0
    height = 100.0

    [faults]                    # optional: a lossy wire between robots (FaultsConfig)
    loss = 0.1
    delay = [0.0, 0.2]

    [layers]                    # optional: replace levels of the app's stack
    task = "my_package.tasks.PatientTask"

    [robots]                    # every other key belongs to the application
    count = 40

A file may start from another one: ``extends = "base.toml"`` (a path relative to
the file) reads the base first, then this file's keys on top of it, table by
table (arrays and values are replaced, not merged). Variants of a scenario are
then a few lines each.

:func:`load_scenario` reads it, applies ``--set key=value`` overrides, imports
the application, validates ``[run]``, ``[world]``, ``[faults]``, ``[layers]`` and the
application's keys (into ``app.config_type``, see
:mod:`~cas_async.scenario._spec._config`), checks that
the machine can hold the robots they make (see :mod:`~cas_async.scenario._spec._capacity`),
then lets the application check what needs several keys at once. Every problem found is
reported in one :class:`~cas_async.scenario._spec._config.ScenarioError` naming the file.

``[layers]`` replaces levels of the app's stack, named by name or index (0 is the
top), by class paths (``"package.module.Class"`` or ``"package.module:Class"``); see
:mod:`~cas_async.scenario._spec._layers` for what is checked. The paths stay in
:attr:`Scenario.data`: a worker that validates the same data gets the same classes.
"""

from __future__ import annotations

import copy
import os
import tomllib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final, Literal

import numpy as np

from ..._core._layer import Layer
from ..._core._supervision import RestartPolicy
from ..._core._transport_contract import Transport
from ..._time._clock import Clock, ScaledClock, VirtualClock
from ..._types import RobotId
from ...sim._environment import Environment
from ...transport._faulty import Faults
from ._app import SimulationApp, SimulationSetup
from ._app_import import RESERVED, import_app, robot_counts
from ._capacity import Capacity, capacity_problems
from ._config import ScenarioError, from_toml, setting, show
from ._layers import layer_classes

__all__ = [
    "FaultsConfig",
    "NetworkConfig",
    "RunConfig",
    "Scenario",
    "WorldConfig",
    "apply_overrides",
    "load_scenario",
    "parse_override",
]


@dataclass(frozen=True, slots=True)
class RunConfig:
    """How a scenario runs: the optional ``[run]`` table.

    Attributes:
        seed: seed of the run's random generator; the same seed replays the same run.
        virtual: run on virtual time (as fast as the CPU allows) instead of
            scaled real time.
        time_factor: with real time, simulated seconds per wall second.
        transport: ``"udp"`` (real sockets on localhost) or ``"memory"`` (in process).
        pass_objects: with the memory transport, pass message objects instead of
            encoding them (see :mod:`cas_async._wire._payloads`): faster, without the
            datagram size and encodability checks. Not with ``[faults]``, which act
            on bytes.
        max_time: simulated seconds after which the run gives up (timed out).
        trace_interval: simulated seconds between two samples of robot positions.
        trace_exchanges: also snapshot every robot's position right after each
            exchange. That costs robots x exchanges in memory, which grows with the
            square of a swarm that scales its work with its size: turn it off for
            thousands of robots (the figures by exchange are then left empty).
        progress_interval: wall seconds between two plain progress lines.
        restarts: how many times a layer that raises is restarted (see
            :mod:`cas_async._core._supervision`) within ``restart_window`` simulated
            seconds; 0 (the default): the first failure fails the run.
        restart_window: the window over which ``restarts`` are counted.
        partition: across processes, which worker runs which robot: ``"region"``
            (strips of the world, neighbours together) or ``"round_robin"`` (see
            :mod:`cas_async.scenario._processes._partition`). Results do not depend on it.
        window_limit: across processes, wall seconds the world waits for a window
            (or a worker's start) before it fails the run, naming who it waited for.
        credit: on virtual time with a latency, the length of a *step*, simulated
            seconds: windows end at every step; a run decided (completed, or every
            robot stopped) in one step runs on, unobserved, to the end of the next,
            in one process as in many; and across processes, the workers run at
            most two steps ahead of what the world has observed. ``None``: ten
            latencies (see :attr:`Scenario.credit`).
    """

    seed: int = setting(0, ge=0, doc="seed of the run's random generator")
    virtual: bool = setting(False, doc="virtual time instead of scaled real time")
    time_factor: float = setting(50.0, gt=0, doc="simulated seconds per wall second")
    transport: Literal["udp", "memory", "zenoh"] = setting(
        "udp", doc="how robots exchange messages (zenoh: the zenoh extra)"
    )
    pass_objects: bool = setting(
        False, doc="memory transport: pass message objects instead of encoding them"
    )
    max_time: float = setting(3600.0, gt=0, doc="simulated seconds before the run gives up")
    trace_interval: float = setting(1.0, gt=0, doc="simulated seconds between position samples")
    trace_exchanges: bool = setting(
        True, doc="snapshot every robot's position after each exchange (robots x exchanges)"
    )
    progress_interval: float = setting(1.0, gt=0, doc="wall seconds between progress lines")
    restarts: int = setting(
        0, ge=0, doc="times a failed layer is restarted within restart_window; 0: the run fails"
    )
    restart_window: float = setting(
        60.0, gt=0, doc="simulated seconds over which restarts are counted"
    )
    partition: Literal["region", "round_robin"] = setting(
        "region", doc="across processes: robots by region of the world, or in turn"
    )
    window_limit: float = setting(
        30.0, gt=0, le=3600, doc="across processes: wall seconds a window may take at most"
    )
    credit: float | None = setting(
        None,
        gt=0,
        le=3600,
        doc="simulated seconds a step lasts: a run ends at the end of the step after the one "
        "it was decided in, and workers run two steps ahead of its observation at most "
        "(default: 10 latencies)",
    )

    @property
    def restart(self) -> RestartPolicy | None:
        """The restart policy robots get, ``None`` when a failed layer fails the run."""
        if not self.restarts:
            return None
        return RestartPolicy(self.restarts, self.restart_window)


CREDIT_LATENCIES: Final = 10
"""``run.credit``'s default, in latencies."""
DEFAULT_LATENCY: Final = 0.005
"""Simulated seconds of the network model when a scenario says nothing (see NetworkConfig)."""


@dataclass(frozen=True, slots=True)
class NetworkConfig:
    """The simulation's network model: the optional ``[network]`` table.

    Attributes:
        latency: simulated seconds any effect takes from one robot to another: a
            datagram sent at ``t`` is delivered at ``t + latency``, a motion is seen
            by the others ``latency`` after it started, an item handed over arrives
            ``latency`` later (see :mod:`cas_async._time._deliveries`). It is what lets a
            run spread over processes go a window of ``latency`` without asking the
            others, and give the very results of a run in one process. 0: every
            effect at once, in one process only. Over UDP or Zenoh (scaled real
            time) datagrams take the real network's own latency; the Environment's
            motions and items keep the model's.
        range: the interaction range: the furthest, in distance units, a robot senses
            (range queries) and its messages and hands reach. A datagram to a robot
            beyond it is lost (``transport.out_of_range``), a wider query or reach is
            an error naming it. It lets a run across processes hold and watch only
            the robots near each worker's own (see docs/processes.md). ``None``: no
            limit.
    """

    latency: float = setting(
        DEFAULT_LATENCY, ge=0, le=60, doc="simulated seconds from one robot to another"
    )
    range: float | None = setting(
        None, gt=0, le=1e9, doc="the furthest a robot senses, and its messages reach (no limit)"
    )


@dataclass(frozen=True, slots=True)
class WorldConfig:
    """The area robots live in: the required ``[world]`` table, corner at ``(0, 0)``.

    Attributes:
        width: extent along x, in distance units.
        height: extent along y, in distance units.
    """

    width: float = setting(gt=0, doc="extent along x, distance units")
    height: float = setting(gt=0, doc="extent along y, distance units")


@dataclass(frozen=True, slots=True)
class FaultsConfig:
    """A lossy wire between the robots: the optional ``[faults]`` table.

    Every datagram a robot sends meets these faults (see
    :class:`~cas_async.transport._faulty.FaultyTransport`); all zero, the default,
    leaves the transport as it is.

    Attributes:
        loss: probability that a datagram is lost.
        duplicate: probability that a datagram is delivered twice.
        reorder: probability that a datagram is held back so later ones overtake it.
        delay: ``[min, max]`` extra latency, simulated seconds, drawn uniformly.
        seed: seed of the faults' random generator; the run's seed when absent.
    """

    loss: float = setting(0.0, ge=0, le=1, doc="probability a datagram is lost")
    duplicate: float = setting(0.0, ge=0, le=1, doc="probability a datagram arrives twice")
    reorder: float = setting(0.0, ge=0, le=1, doc="probability a datagram is overtaken")
    delay: tuple[float, float] = setting(
        (0.0, 0.0), ge=0, doc="[min, max] extra latency, simulated seconds"
    )
    seed: int | None = setting(None, ge=0, doc="seed of the faults (default: the run's seed)")

    def as_faults(self) -> Faults:
        """The :class:`~cas_async.transport._faulty.Faults` these settings describe.

        Raises:
            ValueError: ``delay``'s min is above its max (the loader reports it first).
        """
        return Faults(self.loss, self.duplicate, self.reorder, self.delay)


@dataclass(frozen=True, slots=True)
class Scenario:
    """A loaded, valid scenario.

    Attributes:
        path: the scenario file.
        app_path: the application's import path, as written in the file.
        app: the application.
        run: the ``[run]`` table.
        world: the ``[world]`` table.
        config: the application's keys, an instance of ``app.config_type``.
        data: the file's TOML data after overrides (plain dicts and lists),
            to record with the results.
        faults: the ``[faults]`` table (no faults when absent).
        layers: the classes ``[layers]`` puts in place of the app's own, by slot
            name (checked; empty when absent).
        network: the ``[network]`` table.
    """

    path: Path
    app_path: str
    app: SimulationApp[Any]
    run: RunConfig
    world: WorldConfig
    config: Any
    data: dict[str, Any]
    faults: FaultsConfig = FaultsConfig()
    layers: Mapping[str, type[Layer]] = field(default_factory=dict)
    network: NetworkConfig = NetworkConfig()

    @property
    def credit(self) -> float:
        """``run.credit``, or ten latencies (see :class:`RunConfig`)."""
        if self.run.credit is not None:
            return self.run.credit
        return CREDIT_LATENCIES * self.network.latency

    def clock(self) -> Clock:
        """A new clock for a run: virtual, or scaled by ``run.time_factor``."""
        return VirtualClock() if self.run.virtual else ScaledClock(self.run.time_factor)

    def environment(self, clock: Clock) -> Environment:
        """A new, empty Environment for a run on ``clock``, with the ``[network]`` model."""
        network = self.network
        return Environment(latency=network.latency, clock=clock, interaction_range=network.range)

    def setup(
        self,
        environment: Environment,
        clock: Clock,
        transport: Transport,
        share: frozenset[RobotId] | None = None,
    ) -> SimulationSetup[Any]:
        """What the app builds with: this scenario's settings, seed, restart policy and layers.

        ``share``: the robots this process runs (see :meth:`SimulationSetup.holds`).
        """
        return SimulationSetup(
            self.config,
            (self.world.width, self.world.height),
            environment,
            clock,
            transport,
            np.random.default_rng(self.run.seed),
            self.run.restart,
            layers=self.layers,
            share=share,
        )


def load_scenario(path: str | os.PathLike[str], overrides: Sequence[str] = ()) -> Scenario:
    """Reads, overrides, imports, validates and checks a scenario file.

    Args:
        path: the TOML file.
        overrides: ``"key=value"`` texts, as given to ``--set`` (see :func:`parse_override`),
            applied in order.

    Raises:
        ScenarioError: with ``file`` set to ``path`` as given: the file cannot be
            read or is not TOML, an override is malformed, ``app`` cannot be
            imported, keys are invalid (all of them reported), or the
            application's ``check`` refused the configuration.
    """
    file = os.fspath(path)
    try:
        data = apply_overrides(_read_extended(Path(file)), [parse_override(t) for t in overrides])
        return _validate(Path(file), data)
    except ScenarioError as error:
        located = error.with_file(file).with_traceback(error.__traceback__)
        raise located from error.__cause__


def scenario_from_data(path: Path, data: dict[str, Any]) -> Scenario:
    """Validates a scenario's data as read (and overridden) elsewhere: a worker's copy.

    Raises:
        ScenarioError: as :func:`load_scenario`, reported against ``path``.
    """
    try:
        return _validate(path, data)
    except ScenarioError as error:
        raise error.with_file(str(path)) from error.__cause__


def parse_override(text: str) -> tuple[str, Any]:
    """Splits ``"robots.speed=3"`` into ``("robots.speed", 3)``.

    The value is read as a TOML value (``3``, ``2.5``, ``true``, ``"text"``,
    ``[1, 2]``); anything that is not one is kept as text, so
    ``strategy.name=random`` needs no quotes.

    Raises:
        ScenarioError: on key ``--set``: no ``=``, or an empty key or key part.
    """
    key, equals, value = text.partition("=")
    parts = [part.strip() for part in key.split(".")]
    if not equals or not all(parts):
        raise ScenarioError([("--set", f"expected KEY=VALUE such as robots.speed=3, got {text!r}")])
    return ".".join(parts), _parse_value(value)


def _parse_value(text: str) -> Any:
    try:
        parsed = tomllib.loads(f"v = {text}")
    except tomllib.TOMLDecodeError:
        return text.strip()
    # A value with a line break could smuggle in more keys: take it as text.
    return parsed["v"] if parsed.keys() == {"v"} else text.strip()


def apply_overrides(
    data: Mapping[str, Any], overrides: Iterable[tuple[str, Any]]
) -> dict[str, Any]:
    """A deep copy of ``data`` with each dotted key set to its value, in order.

    Tables on the way that do not exist are created.

    Raises:
        ScenarioError: on key ``--set``, for each override that would go
            through a value that is not a table (``run.seed.x`` when ``seed`` is 7).
    """
    result = copy.deepcopy(dict(data))
    problems = []
    for key, value in overrides:
        *path, last = key.split(".")
        table = result
        for depth, part in enumerate(path, start=1):
            table = table.setdefault(part, {})
            if not isinstance(table, dict):
                where = ".".join(path[:depth])
                problems.append(
                    (
                        "--set",
                        f"cannot set {key}={show(value)}: {where} is {show(table)}, not a table",
                    )
                )
                break
        else:
            table[last] = copy.deepcopy(value)
    if problems:
        raise ScenarioError(problems)
    return result


def _read(path: Path) -> dict[str, Any]:
    try:
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise ScenarioError([("", "no such file")]) from None
    except OSError as error:
        raise ScenarioError([("", f"cannot read the file: {error.strerror or error}")]) from None
    except UnicodeDecodeError as error:
        raise ScenarioError([("", f"not UTF-8 text (byte {error.start})")]) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:  # its message gives the line and column
        raise ScenarioError([("", f"not valid TOML: {error}")]) from None


def _read_extended(path: Path, seen: tuple[Path, ...] = ()) -> dict[str, Any]:
    """The file's data on top of the file it ``extends`` (recursively)."""
    data = _read(path) if not seen else _read_base(path)
    base = data.pop("extends", None)
    if base is None:
        return data
    if not isinstance(base, str) or not base:
        raise ScenarioError([("extends", f"expected a path to a TOML file, got {show(base)}")])
    base_path = path.parent / base
    chain = (*seen, path)
    if base_path.resolve() in {p.resolve() for p in chain}:
        names = " -> ".join(p.name for p in (*chain, base_path))
        raise ScenarioError([("extends", f"files extend each other in a loop: {names}")])
    return _merged(_read_extended(base_path, chain), data)


def _read_base(path: Path) -> dict[str, Any]:
    try:
        return _read(path)
    except ScenarioError as error:  # the error names the extending file: say which base
        raise ScenarioError([("extends", f"{path}: {p}") for _, p in error.problems]) from None


def _merged(base: dict[str, Any], top: Mapping[str, Any]) -> dict[str, Any]:
    merged = dict(base)
    for key, value in top.items():
        below = merged.get(key)
        if isinstance(below, dict) and isinstance(value, dict):
            merged[key] = _merged(below, value)
        else:
            merged[key] = value
    return merged


def _validate(path: Path, data: dict[str, Any]) -> Scenario:
    problems: list[tuple[str, str]] = []
    app_path, app = import_app(data.get("app"), problems, path)
    run_table = data.get("run", {})
    if isinstance(run_table, dict) and run_table.get("virtual") is True:
        # Virtual time runs only in memory: that is the transport unless one is named.
        run_table = {"transport": "memory", **run_table}
    run = _section(RunConfig, run_table, "run", problems)
    world = _section(WorldConfig, data.get("world", {}), "world", problems)
    faults = _section(FaultsConfig, data.get("faults", {}), "faults", problems)
    network = _section(NetworkConfig, data.get("network", {}), "network", problems)
    if faults is not None and faults.delay[0] > faults.delay[1]:
        problems.append(
            ("faults.delay", f"expected [min, max] with min <= max, got {show(faults.delay)}")
        )
    config = None
    layers: dict[str, type[Layer]] = {}
    if app is not None:
        config = _section(app.config_type, data, "", problems, others=RESERVED)
        layers = layer_classes(data.get("layers"), app, problems, path)
    if run is not None and run.virtual and run.transport == "udp":
        problems.append(
            (
                "run.transport",
                'virtual time needs the memory transport: set transport = "memory", '
                "or run on scaled real time (virtual = false)",
            )
        )
    if run is not None and run.pass_objects and run.transport != "memory":
        problems.append(
            ("run.pass_objects", 'objects are passed only in memory: set transport = "memory"')
        )
    if (
        run is not None
        and run.pass_objects
        and faults is not None
        and faults.delay[0] <= faults.delay[1]  # else reported above
        and faults.as_faults().any
    ):
        problems.append(
            (
                "run.pass_objects",
                "[faults] act on datagrams (bytes): turn pass_objects off to use them",
            )
        )
    if (
        run is not None
        and network is not None
        and run.credit is not None
        and run.credit < network.latency
    ):
        problems.append(
            (
                "run.credit",
                f"expected at least network.latency ({network.latency:g} s), got {run.credit:g}",
            )
        )
    if problems or app is None or run is None or world is None or faults is None or network is None:
        raise ScenarioError(problems)
    # Sizes before anything that takes time or memory in proportion to them.
    too_many = capacity_problems(
        robot_counts(app, app_path, config),
        run.transport,
        Capacity.of_this_machine(),
        samples=run.max_time / run.trace_interval,
    )
    if too_many:
        raise ScenarioError(too_many)
    app.check(config, (world.width, world.height))
    return Scenario(path, app_path, app, run, world, config, data, faults, layers, network)


def _section(
    cls: type[Any],
    data: Any,
    key: str,
    problems: list[tuple[str, str]],
    others: frozenset[str] = frozenset(),
) -> Any:
    """``cls`` read from ``data``, or ``None`` with its problems added to ``problems``."""
    try:
        return from_toml(cls, data, key=key, others=others)
    except ScenarioError as error:
        problems.extend(error.problems)
        return None
