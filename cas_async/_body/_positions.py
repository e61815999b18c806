"""A snapshot of where some robots are: ids and coordinates as numpy arrays."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

__all__ = ["Positions"]


@dataclass(frozen=True, slots=True, eq=False)
class Positions:
    """Robot ids and their positions at one simulated instant, row for row.

    The arrays are read-only: they may be shared with a cache.

    Attributes:
        ids: robot ids, shape ``(n,)``, ``int64``.
        xy: positions, shape ``(n, 2)``, ``float64``; row ``k`` belongs to ``ids[k]``.
    """

    ids: npt.NDArray[np.int64]
    xy: npt.NDArray[np.float64]

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    def as_dict(self) -> dict[int, tuple[float, float]]:
        """``{robot_id: (x, y)}``, convenient for small results."""
        return {
            int(robot_id): (float(x), float(y))
            for robot_id, (x, y) in zip(self.ids.tolist(), self.xy.tolist(), strict=True)
        }
