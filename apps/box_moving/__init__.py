"""Two (or more) robots moving boxes, the thesis's second system (§3.2.1, §4.4): see the README.

``app`` is what a scenario file names (``app = "apps.box_moving"``). Four layers,
top first: Decision-Making, Task, Coordination, Action. To try another balancing
rule, subclass :class:`Coordination`, override ``choose_sides``, and name it in
the scenario: ``[layers] coordination = "my_module.MyCoordination"``.
"""

from .action import Action
from .app import MESSAGES, BoxMoving
from .base import BoxLayer, Params, Shared
from .coordination import Coordination
from .coordination_fixed import FixedSideCoordination
from .decision_making import DecisionMaking
from .floor import Floor
from .gripper import FloorGripper, Gripper
from .objective import MoveObjects
from .records import Box, FloorViolation
from .task import Task

__all__ = [
    "MESSAGES",
    "Action",
    "Box",
    "BoxLayer",
    "BoxMoving",
    "Coordination",
    "DecisionMaking",
    "FixedSideCoordination",
    "Floor",
    "FloorGripper",
    "FloorViolation",
    "Gripper",
    "MoveObjects",
    "Params",
    "Shared",
    "Task",
    "app",
]

app = BoxMoving()
"""The app object the scenario runner loads."""
