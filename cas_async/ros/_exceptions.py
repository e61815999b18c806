"""What goes wrong between cas_async and a ROS 2 robot, beside ``ConfigurationError``.

* :class:`~cas_async.ConfigurationError`: a bad endpoint, no router answering, an
  unknown type, an unsupported distribution, a robot whose topic has another type
  or type hash than ours (refused by :class:`~cas_async.ros.RosDiffDrive`).
* :class:`RosTimeout` (also ``TimeoutError``): the robot did not appear, stopped
  sending odometry, or did not reach a goal in time.
* :class:`RosTypeMismatchWarning`: a peer's token shows one of our topics with
  another type or type hash: the two will never hear each other (their keys differ).
"""

from __future__ import annotations

from .. import CasError

__all__ = ["RosTimeout", "RosTypeMismatchWarning"]


class RosTimeout(CasError, TimeoutError):
    """A ROS robot did not do in time what was waited for; the message says what and where."""


class RosTypeMismatchWarning(UserWarning):
    """A peer uses one of our topics with another type or type hash (another distribution?)."""
