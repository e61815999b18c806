"""The ``ros`` extra: Eclipse Zenoh and rosbags, imported when first used.

``import cas_async.ros`` works without them (a user reads the docs, a type checker
reads the names); opening a link or resolving a ROS type imports them, and fails
with the one line that says how to install them.
"""

from __future__ import annotations

from typing import Any, Final

from .. import ConfigurationError

__all__ = ["INSTALL", "import_rosbags_typesys", "import_zenoh"]

INSTALL: Final = 'pip install "cas_async[ros]"'
"""What to run when the extra is missing."""


def import_zenoh() -> Any:
    """The ``zenoh`` module, or a ``ConfigurationError`` saying how to install it."""
    try:
        import zenoh
    except ImportError as exc:
        raise ConfigurationError(
            f"cas_async.ros needs eclipse-zenoh and rosbags: {INSTALL}"
        ) from exc
    return zenoh


def import_rosbags_typesys() -> Any:
    """``rosbags.typesys``, or a ``ConfigurationError`` saying how to install it."""
    try:
        from rosbags import typesys
    except ImportError as exc:
        raise ConfigurationError(
            f"cas_async.ros needs eclipse-zenoh and rosbags: {INSTALL}"
        ) from exc
    return typesys
