"""Transports: how a robot's external messages move, one module per way of moving bytes.

For transport authors: implement :class:`Transport` (one shared object) and
:class:`Endpoint` (one per robot); deliver what arrives to the robot's
:class:`DatagramSink`. :class:`Codec` is the wire format robots encode with, and
:meth:`Codec.for_stack` builds the one a robot of a given stack uses (to craft or
read datagrams in tests and tools).

The transports that ship (also exported by ``cas_async``): :class:`MemoryTransport`,
:class:`UdpTransport`, :class:`ZenohTransport` (with the ``zenoh`` extra), and the
wrappers :class:`FaultyTransport` and :class:`AuthenticatedTransport`.
"""

from .._core._transport_contract import (
    DatagramSink,
    Endpoint,
    LossCounter,
    Transport,
    drop_socket_error,
)
from .._wire._codec import DEFAULT_MAX_DATAGRAM, Codec
from .._wire._fingerprint import describe_fingerprint, stack_fingerprint
from .._wire._payloads import PassThrough, WireCodec
from .._wire._swarm_key import KeyFileWarning, SwarmKey
from ._authenticated import AuthenticatedTransport
from ._faulty import Faults, FaultyTransport
from ._memory import MemoryTransport
from ._udp import MAX_UDP_PAYLOAD, InsecureBindWarning, UdpDirectory, UdpTransport
from .zenoh import ZenohTransport

__all__ = [
    "AuthenticatedTransport",
    "Codec",
    "DEFAULT_MAX_DATAGRAM",
    "DatagramSink",
    "Endpoint",
    "Faults",
    "FaultyTransport",
    "InsecureBindWarning",
    "KeyFileWarning",
    "LossCounter",
    "MAX_UDP_PAYLOAD",
    "MemoryTransport",
    "PassThrough",
    "SwarmKey",
    "Transport",
    "UdpDirectory",
    "UdpTransport",
    "WireCodec",
    "ZenohTransport",
    "describe_fingerprint",
    "drop_socket_error",
    "stack_fingerprint",
]
