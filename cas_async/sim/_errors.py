"""The one exception the simulation kit adds to the cas_async hierarchy.

It sits under :class:`~cas_async._errors.CasError` and is also a ``ValueError``,
so callers may catch either. The kit otherwise reuses the package's errors:
an unknown robot id raises :class:`~cas_async._errors.UnknownRobotError`, a
duplicate robot id :class:`~cas_async._errors.ConfigurationError`, and a second
move started while one is under way :class:`~cas_async._errors.RobotStateError`.
"""

from __future__ import annotations

from .._errors import CasError

__all__ = ["SimulationError"]


class SimulationError(CasError, ValueError):
    """A simulation input is not valid.

    Raised for a non-finite coordinate or heading, a negative or non-finite speed,
    a minimum speed above the initial one, a non-positive turn rate, a negative
    range, or a move asked of an immobile robot. The message names the value.
    """
