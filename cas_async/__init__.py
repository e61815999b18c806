"""cas_async: an asyncio runtime for collaborative autonomous systems.

Robots are stacks of layers that run concurrently, talk to their neighbouring
layers inside the robot, and to the same-level layer of other robots. The
documentation's Concepts page (docs/concepts.md) maps the thesis's names to these.

This package is the face for layer authors and for whoever assembles robots into
a swarm. Transport authors find more in :mod:`cas_async.transport`, simulation
authors in :mod:`cas_async.sim`, application and scenario authors in
:mod:`cas_async.scenario`. Every module or folder with a leading underscore is
internal: the runtime in ``_core``, the wire in ``_wire``, time in ``_time``, the
robot's body in ``_body`` and the command line in ``_cli`` (docs/layout.md).

Each name is imported when first used: ``import cas_async`` costs almost nothing,
so ``python -m cas_async`` takes over SIGINT and SIGTERM before the imports that
take time (see ``cas_async.__main__``), and a program pays only for what it uses.
Type checkers and the API reference read the imports below.
"""

import importlib as _importlib
import typing as _typing

from ._deprecation import Heir as _Heir
from ._deprecation import moved_names as _moved_names

if _typing.TYPE_CHECKING:
    from ._body._middleware import Hands as Hands
    from ._body._middleware import Middleware as Middleware
    from ._body._pose import Pose as Pose
    from ._body._pose import normalize_angle as normalize_angle
    from ._body._positions import Positions as Positions
    from ._body._profiles import (
        ConstantSpeed as ConstantSpeed,
    )
    from ._body._profiles import (
        Decelerating as Decelerating,
    )
    from ._body._profiles import (
        PiecewiseSpeed as PiecewiseSpeed,
    )
    from ._body._profiles import (
        SpeedProfile as SpeedProfile,
    )
    from ._core._counters import LayerCounters as LayerCounters
    from ._core._layer import Layer as Layer
    from ._core._robot import Robot as Robot
    from ._core._robot_state import RobotState as RobotState
    from ._core._supervision import RestartPolicy as RestartPolicy
    from ._core._swarm import Swarm as Swarm
    from ._errors import (
        CasError as CasError,
    )
    from ._errors import (
        ConfigurationError as ConfigurationError,
    )
    from ._errors import (
        DecodeError as DecodeError,
    )
    from ._errors import (
        EncodeError as EncodeError,
    )
    from ._errors import (
        LayerError as LayerError,
    )
    from ._errors import (
        MessageDefinitionError as MessageDefinitionError,
    )
    from ._errors import (
        RequestTimeout as RequestTimeout,
    )
    from ._errors import (
        RobotGone as RobotGone,
    )
    from ._errors import (
        RobotStateError as RobotStateError,
    )
    from ._errors import (
        RuleViolation as RuleViolation,
    )
    from ._errors import (
        SimulationError as SimulationError,
    )
    from ._errors import (
        StackMismatchError as StackMismatchError,
    )
    from ._errors import (
        UnexpectedReply as UnexpectedReply,
    )
    from ._errors import (
        UnknownRobotError as UnknownRobotError,
    )
    from ._time._clock import (
        Clock as Clock,
    )
    from ._time._clock import (
        ScaledClock as ScaledClock,
    )
    from ._time._clock import (
        VirtualClock as VirtualClock,
    )
    from ._time._loop_factory import (
        loop_factory as loop_factory,
    )
    from ._time._loop_factory import (
        run as run,
    )
    from ._time._loop_factory import (
        uvloop_available as uvloop_available,
    )
    from ._time._virtual_loop import VirtualTimeLoop as VirtualTimeLoop
    from ._time._wall import wall_bounded as wall_bounded
    from ._types import Address as Address
    from ._types import ItemId as ItemId
    from ._types import Level as Level
    from ._types import RobotId as RobotId
    from ._wire._message import (
        Finite as Finite,
    )
    from ._wire._message import (
        Message as Message,
    )
    from ._wire._message import (
        MsgType as MsgType,
    )
    from ._wire._message import (
        finite as finite,
    )
    from ._wire._message import (
        message as message,
    )
    from ._wire._message import (
        message_fields as message_fields,
    )
    from ._wire._swarm_key import KeyFileWarning as KeyFileWarning
    from ._wire._swarm_key import SwarmKey as SwarmKey
    from .transport import (
        AuthenticatedTransport as AuthenticatedTransport,
    )
    from .transport import (
        Faults as Faults,
    )
    from .transport import (
        FaultyTransport as FaultyTransport,
    )
    from .transport import (
        InsecureBindWarning as InsecureBindWarning,
    )
    from .transport import (
        MemoryTransport as MemoryTransport,
    )
    from .transport import (
        Transport as Transport,
    )
    from .transport import (
        UdpDirectory as UdpDirectory,
    )
    from .transport import (
        UdpTransport as UdpTransport,
    )
    from .transport import (
        ZenohTransport as ZenohTransport,
    )

__version__ = "0.2.0"

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
    "message_fields",
    "normalize_angle",
    "run",
    "uvloop_available",
    "wall_bounded",
]

_HOMES: _typing.Final[dict[str, str]] = {
    "Hands": "._body._middleware",
    "Middleware": "._body._middleware",
    "Pose": "._body._pose",
    "normalize_angle": "._body._pose",
    "Positions": "._body._positions",
    "ConstantSpeed": "._body._profiles",
    "Decelerating": "._body._profiles",
    "PiecewiseSpeed": "._body._profiles",
    "SpeedProfile": "._body._profiles",
    "LayerCounters": "._core._counters",
    "Layer": "._core._layer",
    "Robot": "._core._robot",
    "RobotState": "._core._robot_state",
    "RestartPolicy": "._core._supervision",
    "Swarm": "._core._swarm",
    "CasError": "._errors",
    "ConfigurationError": "._errors",
    "DecodeError": "._errors",
    "EncodeError": "._errors",
    "LayerError": "._errors",
    "MessageDefinitionError": "._errors",
    "RequestTimeout": "._errors",
    "RobotGone": "._errors",
    "RobotStateError": "._errors",
    "RuleViolation": "._errors",
    "SimulationError": "._errors",
    "StackMismatchError": "._errors",
    "UnexpectedReply": "._errors",
    "UnknownRobotError": "._errors",
    "Clock": "._time._clock",
    "ScaledClock": "._time._clock",
    "VirtualClock": "._time._clock",
    "loop_factory": "._time._loop_factory",
    "run": "._time._loop_factory",
    "uvloop_available": "._time._loop_factory",
    "VirtualTimeLoop": "._time._virtual_loop",
    "wall_bounded": "._time._wall",
    "Address": "._types",
    "ItemId": "._types",
    "Level": "._types",
    "RobotId": "._types",
    "Finite": "._wire._message",
    "Message": "._wire._message",
    "MsgType": "._wire._message",
    "finite": "._wire._message",
    "message": "._wire._message",
    "message_fields": "._wire._message",
    "KeyFileWarning": "._wire._swarm_key",
    "SwarmKey": "._wire._swarm_key",
    "AuthenticatedTransport": ".transport",
    "Faults": ".transport",
    "FaultyTransport": ".transport",
    "InsecureBindWarning": ".transport",
    "MemoryTransport": ".transport",
    "Transport": ".transport",
    "UdpDirectory": ".transport",
    "UdpTransport": ".transport",
    "ZenohTransport": ".transport",
}
"""Where each public name is defined, relative to this package."""

_SUBPACKAGES: _typing.Final = frozenset(
    {"live", "rl", "ros", "scenario", "sim", "testing", "transport"}
)
"""The public faces reachable as attributes once ``cas_async`` is imported."""

_LEGACY = "cas_async._wire._legacy"
_deprecated = _moved_names(
    __name__,
    {
        "Bounds": _Heir(
            _LEGACY,
            advice="write Annotated[float, msgspec.Meta(ge=...)], or cas_async.finite(ge=...) "
            "to refuse infinities too",
        ),
        "MessageSpec": _Heir(
            _LEGACY,
            advice="read the class itself: cas_async.message_fields(cls), "
            "msgspec.structs.fields(cls) and cls.__struct_config__.tag",
        ),
        "spec_of": _Heir(
            _LEGACY,
            advice="read the class itself: cas_async.message_fields(cls), "
            "msgspec.structs.fields(cls) and cls.__struct_config__.tag",
        ),
    },
)
"""Names of 0.1.0 that 0.2.0 still gives, with a warning (``CHANGELOG.md``)."""


def __getattr__(name: str) -> object:
    home = _HOMES.get(name)
    if home is not None:
        value = getattr(_importlib.import_module(home, __name__), name)
    elif name in _SUBPACKAGES:
        value = _importlib.import_module(f".{name}", __name__)
    else:
        # A name of an earlier release gives its heir with a warning; else AttributeError.
        return _deprecated(name)
    globals()[name] = value  # the next look-up does not come here
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__, *_SUBPACKAGES})
