"""cas_async: an asyncio runtime for collaborative autonomous systems.

Robots are stacks of layers that run concurrently, talk to their neighbouring
layers inside the robot, and to the same-level layer of other robots. The
documentation's Concepts page (docs/concepts.md) maps the thesis's names to these.

This package is the face for layer authors and for whoever assembles robots into
a swarm. Transport authors find more in :mod:`cas_async.transport`, simulation
authors in :mod:`cas_async.sim`, application and scenario authors in
:mod:`cas_async.scenario`. Every module with a leading underscore is internal.
"""

# ruff: noqa: E402 - the imports below come after the signals are handled
# First, before the imports that take time: `python -m cas_async` exits 130 on a signal.
from . import _interrupts

_interrupts.exit_on_signal_while_importing()

from ._clock import Clock, ScaledClock, VirtualClock
from ._counters import LayerCounters
from ._errors import (
    CasError,
    ConfigurationError,
    DecodeError,
    EncodeError,
    LayerError,
    MessageDefinitionError,
    RequestTimeout,
    RobotGone,
    RobotStateError,
    RuleViolation,
    SimulationError,
    StackMismatchError,
    UnexpectedReply,
    UnknownRobotError,
)
from ._layer import Layer
from ._message import Finite, Message, MsgType, finite, message
from ._middleware import Hands, Middleware
from ._pose import Pose
from ._positions import Positions
from ._profiles import ConstantSpeed, Decelerating, PiecewiseSpeed, SpeedProfile
from ._robot import Robot
from ._robot_state import RobotState
from ._runner import loop_factory, run, uvloop_available
from ._supervision import RestartPolicy
from ._swarm import Swarm
from ._swarm_key import KeyFileWarning, SwarmKey
from ._types import Address, ItemId, Level, RobotId
from ._virtual_loop import VirtualTimeLoop
from .transport import (
    AuthenticatedTransport,
    Faults,
    FaultyTransport,
    InsecureBindWarning,
    MemoryTransport,
    Transport,
    UdpDirectory,
    UdpTransport,
    ZenohTransport,
)

__version__ = "0.1.0"

__all__ = [
    "Address",
    "AuthenticatedTransport",
    "CasError",
    "Clock",
    "ConfigurationError",
    "ConstantSpeed",
    "Decelerating",
    "DecodeError",
    "EncodeError",
    "Faults",
    "FaultyTransport",
    "Finite",
    "Hands",
    "InsecureBindWarning",
    "ItemId",
    "KeyFileWarning",
    "Layer",
    "LayerCounters",
    "LayerError",
    "Level",
    "MemoryTransport",
    "Message",
    "MessageDefinitionError",
    "Middleware",
    "MsgType",
    "PiecewiseSpeed",
    "Pose",
    "Positions",
    "RequestTimeout",
    "RestartPolicy",
    "Robot",
    "RobotGone",
    "RobotId",
    "RobotState",
    "RobotStateError",
    "RuleViolation",
    "ScaledClock",
    "SimulationError",
    "SpeedProfile",
    "StackMismatchError",
    "Swarm",
    "SwarmKey",
    "Transport",
    "UdpDirectory",
    "UdpTransport",
    "UnexpectedReply",
    "UnknownRobotError",
    "VirtualClock",
    "VirtualTimeLoop",
    "ZenohTransport",
    "finite",
    "loop_factory",
    "message",
    "run",
    "uvloop_available",
]
