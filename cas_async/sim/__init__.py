"""A generic 2-D mobile-robot simulation kit: kinematics, an Environment, a middleware.

* :mod:`.pose`, :mod:`.phases`, :mod:`.profiles`, :mod:`.kinematics`: closed-form motion of a
  robot that rotates in place and drives straight under a pluggable speed profile.
* :mod:`.environment`: every simulated robot's motion, exact at any instant,
  with vectorised range queries.
* :mod:`.items`: items robots carry, and a ledger that checks none is lost or
  duplicated.
* :mod:`.middleware`: the seam between robotic layers and the robot, with its
  simulated implementation.

Nothing here knows any application: profiles describe physics, and the
application decides when to change them.
"""

from .environment import Environment
from .errors import SimulationError
from .items import ItemEvent, ItemEventKind, ItemId, ItemLedger
from .kinematics import Motion, check_turn_rate
from .middleware import Middleware, SimulatedMiddleware
from .phases import Phase, check_phases
from .pose import Pose, normalize_angle
from .positions import Positions
from .profiles import ConstantSpeed, Decelerating, PiecewiseSpeed, SpeedProfile, closing_time

__all__ = [
    "ConstantSpeed",
    "Decelerating",
    "Environment",
    "ItemEvent",
    "ItemEventKind",
    "ItemId",
    "ItemLedger",
    "Middleware",
    "Motion",
    "Phase",
    "PiecewiseSpeed",
    "Pose",
    "Positions",
    "SimulatedMiddleware",
    "SimulationError",
    "SpeedProfile",
    "check_phases",
    "check_turn_rate",
    "closing_time",
    "normalize_angle",
]
