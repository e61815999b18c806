"""What the views draw under the robots: the objects where they lie, the zone and its spots.

The scene is static: each object is drawn where it lay when the run began
(a robot carrying one is marked as a carrier), the destination zone as a disc,
and each object's drop spot in it as a cross.
"""

from __future__ import annotations

from collections.abc import Sequence

from cas_async.scenario import Disc, Rect, Scene, Spot

from .geometry import Point
from .records import Box

__all__ = ["floor_scene"]


def floor_scene(boxes: Sequence[Box], zone: tuple[Point, float]) -> Scene:
    """The destination zone, the drop spots, and every object (labelled by its id)."""
    (x, y), radius = zone
    return Scene(
        colors={"object": "#8c6d1f", "destination": "#0072b2", "drop spot": "#0072b2"},
        shapes=[
            Disc(x, y, radius, label="destination", kind="destination"),
            *(Spot(box.drop_x, box.drop_y, kind="drop spot") for box in boxes),
            *(
                Rect(box.x, box.y, box.size, box.size, label=str(box.obj), kind="object")
                for box in boxes
            ),
        ],
    )
