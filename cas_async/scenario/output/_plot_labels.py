"""Robot id labels for the figures that cannot be misread when robots stand together.

A label is written up and to the right of its robot. Two robots closer than a
label's size would get overlapping labels: robots 3 and 1 side by side read as
"31", an id that may not exist. Robots whose labels would overlap share one
label instead, their ids joined by commas in order (``"1,3"``; beyond
:data:`_LISTED` ids, ``"4,5,6 +2"``), written at the first robot of the group.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Final

import numpy as np
import numpy.typing as npt

__all__ = ["id_labels"]

_CHARACTER: Final = 0.008
"""A label character's width, as a fraction of the world's larger side (font ~5-6 pt)."""
_HEIGHT: Final = 0.022
"""A label's height, as the same fraction."""
_LISTED: Final = 3
"""Ids a shared label lists before it says how many more: ``"4,5,6 +2"``."""


def id_labels(
    ids: Sequence[int], xy: npt.NDArray[np.float64], world: tuple[float, float]
) -> list[tuple[str, tuple[float, float]]]:
    """One ``(text, (x, y))`` per group of robots whose labels would overlap.

    Robots are taken in id order; each joins the first group whose first robot
    stands close enough that their labels would overlap, or starts a group.

    Args:
        ids: robot ids, row ``k`` of ``xy`` being robot ``ids[k]``'s position.
        xy: positions, shape ``(n, 2)``.
        world: ``(width, height)``: labels are sized against its larger side.
    """
    side = max(world)
    character, height = _CHARACTER * side, _HEIGHT * side
    groups: list[list[int]] = []  # rows, the first being where the label goes
    anchors: list[tuple[float, float, int]] = []  # x, y, characters of the first id
    for k in sorted(range(len(ids)), key=lambda row: ids[row]):
        x, y = float(xy[k, 0]), float(xy[k, 1])
        width = len(str(ids[k]))
        for group, (ax, ay, chars) in zip(groups, anchors, strict=True):
            if abs(y - ay) < height and abs(x - ax) < character * (max(width, chars) + 1):
                group.append(k)
                break
        else:
            groups.append([k])
            anchors.append((x, y, width))
    return [
        (_text([ids[k] for k in group]), anchor[:2])
        for group, anchor in zip(groups, anchors, strict=True)
    ]


def _text(ids: Sequence[int]) -> str:
    shown = ",".join(str(i) for i in ids[:_LISTED])
    return shown if len(ids) <= _LISTED else f"{shown} +{len(ids) - _LISTED}"
