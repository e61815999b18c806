"""cas_async: an asyncio runtime for collaborative autonomous systems.

Robots are stacks of layers that run concurrently, talk to their neighbouring
layers inside the robot, and to the same-level layer of other robots. See the
README for the thesis-to-API map.
"""

from ._types import Address, Level, RobotId
from .clock import Clock, ScaledClock, VirtualClock
from .codec import DEFAULT_MAX_DATAGRAM, Codec
from .counters import LayerCounters
from .errors import (
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
from .fingerprint import describe_fingerprint, stack_fingerprint
from .layer import Layer
from .message import Message, MessageSpec, MsgType, message, spec_of
from .robot import Robot, RobotState
from .runner import loop_factory, run, uvloop_available
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
from .supervision import RestartPolicy
from .swarm import Swarm
from .swarm_key import KeyFileWarning, SwarmKey
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
from .virtual_loop import VirtualTimeLoop
from .wire_codec import PassThrough, WireCodec

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
