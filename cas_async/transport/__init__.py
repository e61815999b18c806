"""Transports: one module per way of moving a robot's datagrams."""

from .base import DatagramSink, Endpoint, Transport
from .memory import MemoryTransport
from .udp import MAX_UDP_PAYLOAD, UdpDirectory, UdpTransport

__all__ = [
    "MAX_UDP_PAYLOAD",
    "DatagramSink",
    "Endpoint",
    "MemoryTransport",
    "Transport",
    "UdpDirectory",
    "UdpTransport",
]
