"""The simulation kit: kinematics, an Environment, and the simulated middleware and hands.

For simulation authors (a scenario's application builds its robots with these):

* :class:`Environment`: every simulated robot's motion, exact at any instant,
  with vectorised range queries, and the :class:`ItemLedger` of the items robots
  hold, which refuses any loss or duplication;
* :class:`SimulatedMiddleware` and :class:`SimulatedHands`: the robot's
  :class:`~cas_async.Middleware` and :class:`~cas_async.Hands` in an Environment;
* :class:`Motion`, :class:`Phase`, :func:`closing_time`: the closed-form motion
  of a robot that rotates in place and drives straight under a speed profile;
* :class:`RangedTransport`: a simulated radio's reach: datagrams to robots beyond
  the Environment's interaction range are lost, and counted.

Nothing here knows any application: profiles describe physics, and the
application decides when to change them. The vocabulary robotic layers share
with hardware (poses, positions, speed profiles, the middleware interface) is
in the core, ``cas_async``.
"""

from .._body._phases import Phase, check_phases
from .._body._pose import normalize_angle
from .._body._profiles import closing_time
from ._environment import Environment
from ._item_events import ItemEvent, ItemEventKind
from ._items import ItemLedger
from ._kinematics import Motion, check_turn_rate
from ._radio import RangedTransport
from ._simulated import SimulatedHands, SimulatedMiddleware

__all__ = [
    "Environment",
    "ItemEvent",
    "ItemEventKind",
    "ItemLedger",
    "Motion",
    "Phase",
    "RangedTransport",
    "SimulatedHands",
    "SimulatedMiddleware",
    "check_phases",
    "check_turn_rate",
    "closing_time",
    "normalize_angle",
]
