"""The transport a scenario's robots talk over: the wire it names, its faults, the swarm key."""

from __future__ import annotations

from ..._core._transport_contract import Transport
from ..._errors import ConfigurationError
from ..._time._clock import Clock
from ..._wire._swarm_key import SwarmKey
from ...sim._environment import Environment
from ...sim._radio import RangedTransport
from ...transport._authenticated import AuthenticatedTransport
from ...transport._faulty import FaultyTransport
from ...transport._memory import MemoryTransport
from ...transport._udp import UdpTransport
from ...transport.zenoh import ZenohTransport
from ._loader import Scenario

__all__ = ["check_key", "fault_counts", "faulty", "ranged", "run_transport"]


def check_key(scenario: Scenario, key: SwarmKey | None) -> None:
    """Raises ``ConfigurationError`` when ``scenario`` cannot run signed with ``key``."""
    if scenario.run.pass_objects and key is not None:
        raise ConfigurationError(
            f"{scenario.path}: run.pass_objects passes message objects, which a swarm key cannot "
            "sign; set run.pass_objects = false to run with a key"
        )


def run_transport(
    scenario: Scenario, clock: Clock, key: SwarmKey | None, environment: Environment
) -> Transport:
    """The run's transport: its ``[faults]`` and range, if any, and signed with ``key``."""
    run = scenario.run
    check_key(scenario, key)
    transport: Transport
    if run.transport == "memory":
        transport = MemoryTransport(
            pass_objects=run.pass_objects, latency=scenario.network.latency, clock=clock
        )
    elif run.transport == "zenoh":
        if run.virtual:
            raise ConfigurationError(
                f"{scenario.path}: run.transport: virtual time over Zenoh needs processes that "
                "share it: run with --processes N, or on scaled time (virtual = false)"
            )
        transport = ZenohTransport()
    else:
        transport = UdpTransport()
    transport = ranged(faulty(scenario, transport, clock), environment, clock)
    return transport if key is None else AuthenticatedTransport(transport, key)


def ranged(transport: Transport, environment: Environment, clock: Clock) -> Transport:
    """``transport`` losing datagrams beyond the interaction range, if the run has one.

    Outside the faults: a datagram out of range is lost before any fault is drawn
    for it (each robot draws its faults in the order of its own sends).
    """
    if environment.interaction_range is None:
        return transport
    return RangedTransport(transport, environment, clock)


def faulty(scenario: Scenario, transport: Transport, clock: Clock) -> Transport:
    """``transport`` with the scenario's ``[faults]`` on its wire, if it has any."""
    faults = scenario.faults.as_faults()
    if not faults.any:
        return transport
    seed = scenario.run.seed if scenario.faults.seed is None else scenario.faults.seed
    return FaultyTransport(transport, faults, seed=seed, clock=clock)


def fault_counts(transport: Transport) -> dict[str, int] | None:
    """What the ``[faults]`` on ``transport``'s wire did so far, or ``None`` without faults."""
    wire = transport
    while isinstance(wire, AuthenticatedTransport | RangedTransport):
        wire = wire.inner
    return wire.stats if isinstance(wire, FaultyTransport) else None
