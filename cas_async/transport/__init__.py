"""Transports: one module per way of moving a robot's datagrams."""

from .authenticated import AuthenticatedTransport
from .base import DatagramSink, Endpoint, LossCounter, Transport
from .faulty import Faults, FaultyTransport
from .memory import MemoryTransport
from .udp import MAX_UDP_PAYLOAD, InsecureBindWarning, UdpDirectory, UdpTransport

__all__ = [
    "MAX_UDP_PAYLOAD",
    "AuthenticatedTransport",
    "DatagramSink",
    "Endpoint",
    "Faults",
    "FaultyTransport",
    "InsecureBindWarning",
    "LossCounter",
    "MemoryTransport",
    "Transport",
    "UdpDirectory",
    "UdpTransport",
]
