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

from ._environment import Environment
from ._errors import SimulationError
from ._items import ItemEvent, ItemEventKind, ItemId, ItemLedger
from ._kinematics import Motion, check_turn_rate
from ._middleware import Middleware, SimulatedMiddleware
from ._phases import Phase, check_phases
from ._pose import Pose, normalize_angle
from ._positions import Positions
from ._profiles import ConstantSpeed, Decelerating, PiecewiseSpeed, SpeedProfile, closing_time

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
