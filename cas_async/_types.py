"""Type aliases shared across the package, kept in one place."""

from __future__ import annotations

from collections.abc import Hashable
from typing import TypeAlias

__all__ = ["Address", "ItemId", "Level", "RobotId"]

RobotId: TypeAlias = int
"""Identifies a robot within a swarm; unique per swarm."""

Level: TypeAlias = int
"""Position of a layer in a robot's stack: 0 is the top layer."""

Address: TypeAlias = Hashable
"""Where a transport reaches a robot. Opaque to layers: UDP uses ``(host, port)``,
other transports use whatever they need."""

ItemId: TypeAlias = int
"""Identifies an item robots carry (a bucket, a box): 1, 2, 3, ... in order of creation."""
