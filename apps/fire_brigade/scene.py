"""What the views draw under the robots: each station's area and the lines between them.

The Generators and Sinks are robots (they stand still); the scene marks the area
around each, where :class:`~apps.fire_brigade.lines.LineShare` counts no robot as
standing in a line, and the segment from each Generator to its Sink, the line the
Transporters are expected to form (thesis §5.8).
"""

from __future__ import annotations

from collections.abc import Sequence

from cas_async.scenario import Disc, Polyline, Scene

from .base import Point
from .lines import AWAY, segments

__all__ = ["brigade_scene"]


def brigade_scene(generators: Sequence[Point], sinks: Sequence[Point]) -> Scene:
    """The stations' areas (``G1``, ``S1``, ...) and each Generator's line to its Sink."""
    areas = [
        Disc(x, y, AWAY, label=f"{letter}{k}", kind=kind)
        for letter, kind, points in (("G", "Generator", generators), ("S", "Sink", sinks))
        for k, (x, y) in enumerate(points, start=1)
    ]
    lines = [Polyline((start, end), kind="line") for start, end in segments(generators, sinks)]
    return Scene([*lines, *areas])
