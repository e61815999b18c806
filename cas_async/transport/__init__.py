"""Transports: one module per way of moving a robot's datagrams."""

from ._authenticated import AuthenticatedTransport
from ._base import DatagramSink, Endpoint, LossCounter, Transport
from ._faulty import Faults, FaultyTransport
from ._memory import MemoryTransport
from ._udp import MAX_UDP_PAYLOAD, InsecureBindWarning, UdpDirectory, UdpTransport

__all__ = [
    "AuthenticatedTransport",
    "DatagramSink",
    "Endpoint",
    "Faults",
    "FaultyTransport",
    "InsecureBindWarning",
    "LossCounter",
    "MAX_UDP_PAYLOAD",
    "MemoryTransport",
    "Transport",
    "UdpDirectory",
    "UdpTransport",
]
