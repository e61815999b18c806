"""The application a scenario's ``app`` names: imported, and checked against the contract.

``app = "package.module"`` (the module's ``app``) or ``"package.module:attr"``; the
object must satisfy :class:`~cas_async.scenario.SimulationApp`: what it lacks is
reported member by member (``app "x" lacks robots(config) -> ...``), as is a
``config_type`` that is no dataclass or that uses a key the scenario reserves.
"""

from __future__ import annotations

import dataclasses
import importlib
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Final, cast

from ._app import SimulationApp, app_problems
from ._config import ScenarioError, show
from ._layers import importable_from

__all__ = ["RESERVED", "import_app", "robot_counts"]

RESERVED: Final = frozenset({"app", "faults", "layers", "network", "run", "world"})
"""The scenario's own keys: an app's ``config_type`` may not use them."""
_MISSING: Final = object()
_IMPORT_PATH: Final = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*(:[A-Za-z_]\w*)?")
_APP_EXPECTED: Final = 'an import path such as "package.module" or "package.module:attr"'


def import_app(
    spec: object, problems: list[tuple[str, str]], path: Path
) -> tuple[str, SimulationApp[Any] | None]:
    """The application ``spec`` names, or ``None`` with the reason added to ``problems``."""
    if spec is None:
        problems.append(("app", f"missing required key (expected {_APP_EXPECTED})"))
        return "", None
    if not isinstance(spec, str) or not _IMPORT_PATH.fullmatch(spec):
        problems.append(("app", f"expected {_APP_EXPECTED}, got {show(spec)}"))
        return "", None
    module_name, _, attribute = spec.partition(":")
    attribute = attribute or "app"
    importable_from(path, module_name)
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        problems.append(("app", f"cannot import {show(module_name)}: {error}"))
        return spec, None
    app: Any = getattr(module, attribute, _MISSING)
    if app is _MISSING:
        problems.append(("app", f"module {show(module_name)} has no attribute {attribute!r}"))
        return spec, None
    lacking = app_problems(app)
    if lacking:
        contract = "see cas_async.scenario.SimulationApp"
        problems += [("app", f"app {show(spec)} {problem} ({contract})") for problem in lacking]
        return spec, None
    config_type = app.config_type
    if not (isinstance(config_type, type) and dataclasses.is_dataclass(config_type)):
        problems.append(
            ("app", f"{show(spec)}: config_type must be a dataclass, got {config_type!r}")
        )
        return spec, None
    clashes = sorted(RESERVED.intersection(f.name for f in dataclasses.fields(config_type)))
    if clashes:
        problems.append(
            ("app", f"{show(spec)}: config_type may not have keys {', '.join(clashes)}")
        )
        return spec, None
    return spec, cast(SimulationApp[Any], app)


def robot_counts(app: SimulationApp[Any], app_path: str, config: Any) -> Mapping[str, int]:
    """``app.robots(config)``, checked: robot counts by the key that sets each.

    Raises:
        ScenarioError: on key ``app``: the app answered something else.
    """
    counts: object = app.robots(config)
    if isinstance(counts, Mapping) and all(
        isinstance(key, str) and type(n) is int and n >= 0 for key, n in counts.items()
    ):
        return cast(Mapping[str, int], counts)
    raise ScenarioError(
        [
            (
                "app",
                f"app {show(app_path)}: robots(config) returned {counts!r}; expected robot "
                'counts by the key that sets each, such as {"robots.count": 5}',
            )
        ]
    )
