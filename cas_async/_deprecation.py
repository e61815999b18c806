"""Names of an earlier release that work for one more, with a warning naming their heirs.

A face (a package's ``__init__``) hands its ``__getattr__`` the names it no longer
defines (:func:`moved_names`): reading one warns with a :class:`DeprecationWarning`
that says what to use instead, then gives the heir, so a user's code keeps working
while they move. ``CHANGELOG.md`` lists every such name under the release that moved it.
"""

from __future__ import annotations

import importlib
import sys
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Final, final

__all__ = ["REMOVED_IN", "Heir", "moved_names"]

REMOVED_IN: Final = "0.3.0"
_IMPORTLIB: Final = "<frozen importlib._bootstrap>"
"""The release in which the names deprecated now are removed."""


@final
@dataclass(frozen=True, slots=True)
class Heir:
    """What replaces a deprecated name: ``module.name``, or a value built on demand.

    Args:
        module: the absolute module whose ``name`` replaces it.
        name: the name there (the deprecated name when empty).
        advice: what the warning tells the user to do, when ``module.name`` alone
            does not say it (a different way of writing the same thing).
        value: builds what the deprecated name gives, when it is not ``module.name``
            itself (a shim that writes the old call the new way).
    """

    module: str
    name: str = ""
    advice: str = ""
    value: Callable[[], object] | None = None

    def path(self, old: str) -> str:
        """``module.name``, the heir's full name."""
        return f"{self.module}.{self.name or old}"


def moved_names(module: str, heirs: Mapping[str, Heir]) -> Callable[[str], object]:
    """What a face's ``__getattr__`` calls for ``heirs``: each warns, then gives its heir.

    Any other name raises ``AttributeError`` as a module without ``__getattr__`` would.
    The face's ``__getattr__`` must call it directly (the warning names its caller).
    """

    def deprecated(name: str) -> object:
        heir = heirs.get(name)
        if heir is None:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        # ``from face import name`` asks twice: importlib's hasattr, then the import
        # itself. The user hears of it once, from the import.
        if sys._getframe(2).f_code.co_filename != _IMPORTLIB:
            _warn(module, name, heir)
        if heir.value is not None:
            return heir.value()
        return getattr(importlib.import_module(heir.module), heir.name or name)

    return deprecated


def _warn(module: str, name: str, heir: Heir) -> None:
    advice = heir.advice or f"use {heir.path(name)}"
    warnings.warn(
        f"{module}.{name} is deprecated and will be removed in {REMOVED_IN}: {advice}",
        DeprecationWarning,
        stacklevel=4,  # the user's line: past this, deprecated() and the face's __getattr__
    )
