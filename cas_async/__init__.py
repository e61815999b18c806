"""cas_async: an asyncio runtime for collaborative autonomous systems.

Robots are stacks of layers that run concurrently, talk to their neighbouring
layers inside the robot, and to the same-level layer of other robots. See the
README for the thesis-to-API map.
"""

from ._clock import Clock, ScaledClock, VirtualClock
from ._codec import DEFAULT_MAX_DATAGRAM, Codec
from ._counters import LayerCounters
from ._errors import (
    CasError,
    ConfigurationError,
    DecodeError,
    EncodeError,
    LayerError,
    MessageDefinitionError,
    RequestTimeout,
    RobotStateError,
    RuleViolation,
    StackMismatchError,
    UnknownRobotError,
)
from ._fingerprint import describe_fingerprint, stack_fingerprint
from ._layer import Layer
from ._message import Message, MessageSpec, MsgType, message, spec_of
from ._robot import Robot, RobotState
from ._runner import loop_factory, run, uvloop_available
from ._supervision import RestartPolicy
from ._swarm import Swarm
from ._swarm_key import KeyFileWarning, SwarmKey
from ._types import Address, Level, RobotId
from ._virtual_loop import VirtualTimeLoop
from ._wire_codec import PassThrough, WireCodec
from .sim import (
    ConstantSpeed,
    Decelerating,
    Environment,
    ItemEvent,
    ItemEventKind,
    ItemId,
    ItemLedger,
    Middleware,
    Motion,
    Phase,
    PiecewiseSpeed,
    Pose,
    Positions,
    SimulatedMiddleware,
    SimulationError,
    SpeedProfile,
    check_phases,
    check_turn_rate,
    closing_time,
    normalize_angle,
)
from .transport import (
    AuthenticatedTransport,
    DatagramSink,
    Endpoint,
    Faults,
    FaultyTransport,
    InsecureBindWarning,
    LossCounter,
    MemoryTransport,
    Transport,
    UdpDirectory,
    UdpTransport,
)

__version__ = "0.1.0"

__all__ = [
    "Address",
    "AuthenticatedTransport",
    "CasError",
    "Clock",
    "Codec",
    "ConfigurationError",
    "ConstantSpeed",
    "DEFAULT_MAX_DATAGRAM",
    "DatagramSink",
    "Decelerating",
    "DecodeError",
    "EncodeError",
    "Endpoint",
    "Environment",
    "Faults",
    "FaultyTransport",
    "InsecureBindWarning",
    "ItemEvent",
    "ItemEventKind",
    "ItemId",
    "ItemLedger",
    "KeyFileWarning",
    "Layer",
    "LayerCounters",
    "LayerError",
    "Level",
    "LossCounter",
    "MemoryTransport",
    "Message",
    "MessageDefinitionError",
    "MessageSpec",
    "Middleware",
    "Motion",
    "MsgType",
    "PassThrough",
    "Phase",
    "PiecewiseSpeed",
    "Pose",
    "Positions",
    "RequestTimeout",
    "RestartPolicy",
    "Robot",
    "RobotId",
    "RobotState",
    "RobotStateError",
    "RuleViolation",
    "ScaledClock",
    "SimulatedMiddleware",
    "SimulationError",
    "SpeedProfile",
    "StackMismatchError",
    "Swarm",
    "SwarmKey",
    "Transport",
    "UdpDirectory",
    "UdpTransport",
    "UnknownRobotError",
    "VirtualClock",
    "VirtualTimeLoop",
    "WireCodec",
    "check_phases",
    "check_turn_rate",
    "closing_time",
    "describe_fingerprint",
    "loop_factory",
    "message",
    "normalize_angle",
    "run",
    "spec_of",
    "stack_fingerprint",
    "uvloop_available",
]
