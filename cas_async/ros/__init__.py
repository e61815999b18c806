"""ROS 2 robots over rmw_zenoh, with no ROS install: the robotic middleware made real.

Needs the ``ros`` extra (``pip install "cas_async[ros]"``: Eclipse Zenoh and rosbags);
importing this package does not, opening a link does.

* :class:`RosLink`: a ROS 2 node in a Zenoh session connected (as a client) to a
  robot's ``rmw_zenohd``: node and entity liveliness tokens, publishers and
  subscriptions with rmw_zenoh's keys and attachments, types by their ROS names
  with plain Python values in and out, the graph as rmw_zenoh sees it.
* :class:`RosDiffDrive`: a :class:`~cas_async.Middleware` that drives a
  differential-drive robot with ``cmd_vel`` and reads its pose from ``odom``, so a
  layer written against ``Middleware`` drives a simulated or a ROS 2 robot unchanged.
* :class:`FakeRobot` (``python -m cas_async.ros fake-robot``): a stand-in robot
  behind a router configured like ``rmw_zenohd``, for tests and for trying it out.

The wire format is that of rmw_zenoh for ROS 2 Jazzy (:data:`DISTRO`; Kilted too),
as its ``docs/design.md`` describes it; ``docs/ros.md`` says what was tested
against what.
"""

from ._controller import DiffDriveController, DriveTuning
from ._diff_drive import RosDiffDrive
from ._endpoints import RosPublisher, RosSubscription
from ._exceptions import RosTimeout, RosTypeMismatchWarning
from ._fake_robot import FakeRobot
from ._graph import GraphEntity, parse_token
from ._link import RosLink, TypeMismatch
from ._message_types import DISTRO, DISTROS, RosType, TypeCatalog
from ._qos import Durability, History, Liveliness, QoS, Reliability

__all__ = [
    "DISTRO",
    "DISTROS",
    "DiffDriveController",
    "DriveTuning",
    "Durability",
    "FakeRobot",
    "GraphEntity",
    "History",
    "Liveliness",
    "QoS",
    "Reliability",
    "RosDiffDrive",
    "RosLink",
    "RosPublisher",
    "RosSubscription",
    "RosTimeout",
    "RosType",
    "RosTypeMismatchWarning",
    "TypeCatalog",
    "TypeMismatch",
    "parse_token",
]
