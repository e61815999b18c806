"""Transports: one module per way of moving a robot's datagrams."""

from .base import DatagramSink, Endpoint, LossCounter, Transport
from .faulty import Faults, FaultyTransport
from .memory import MemoryTransport
from .udp import MAX_UDP_PAYLOAD, UdpDirectory, UdpTransport

__all__ = [
    "MAX_UDP_PAYLOAD",
    "DatagramSink",
    "Endpoint",
    "Faults",
    "FaultyTransport",
    "LossCounter",
    "MemoryTransport",
    "Transport",
    "UdpDirectory",
    "UdpTransport",
]
