"""What every episode of an env is built from: :class:`Recipe`.

The scenario as given (a file and its overrides, or a loaded one), the level the
policy acts through, and the policy layer's class, which each episode's scenario
names in its ``[layers]`` by path (``layers.<level> = "module:Class"``): the loader
imports and checks it there as it does any replacement.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any, final

from .. import ConfigurationError, RobotId
from ..scenario import Scenario, apply_overrides, load_scenario, parse_override, scenario_from_data
from ._episode import Episode
from ._policy import PolicyLayer

__all__ = ["Recipe", "agent_name"]


@final
class Recipe:
    """The scenario, level and policy layer of an env; :meth:`episode` builds one.

    Args:
        scenario: a scenario file, or a loaded scenario.
        overrides: ``--set`` strings applied to it.
        level: the level's name or index.
        layer: the policy layer's class (``None``: the one ``[layers]`` names there).

    Raises:
        ConfigurationError: ``level`` or ``layer`` cannot work.
        ScenarioError: the scenario or an override is not valid.
    """

    def __init__(
        self,
        scenario: str | os.PathLike[str] | Scenario,
        overrides: Sequence[str],
        level: str | int,
        layer: type[PolicyLayer] | None,
    ) -> None:
        if isinstance(scenario, Scenario):
            if overrides:
                scenario = _revalidated(scenario, [parse_override(text) for text in overrides])
        else:
            scenario = load_scenario(scenario, overrides)
        self.scenario = scenario
        """The scenario as given, with its overrides (its own seed and time)."""
        self._index, self._level = _level_of(scenario, level)
        self._layer = _policy_class(scenario, self._level, layer)
        self._path = _class_path(self._layer)

    def episode(self, seed: int) -> Episode:
        """A new episode: the scenario with ``seed``, on virtual time, the policy at its level.

        Raises:
            ConfigurationError: the class path imports another class than the policy
                layer's (two modules define it), or a robot lacks the policy layer.
            ScenarioError: the scenario refuses the policy layer (``[layers]``'s checks).
        """
        scenario = _revalidated(
            self.scenario,
            [
                (f"layers.{self._level}", self._path),
                ("run.seed", seed),
                ("run.virtual", True),
                ("run.transport", "memory"),
            ],
        )
        if scenario.layers.get(self._level) is not self._layer:
            raise ConfigurationError(
                f"layer: importing {self._path} gives another class than "
                f"{self._layer!r}: define the policy layer once, in a module that "
                "imports by that path"
            )
        return Episode(scenario, self._index)


def agent_name(robot: RobotId) -> str:
    """The agent a robot is (``3``: ``"robot_3"``)."""
    return f"robot_{robot}"


def _revalidated(base: Scenario, overrides: Sequence[tuple[str, Any]]) -> Scenario:
    """``base`` with ``overrides`` applied to its data, validated again as the loader does."""
    return scenario_from_data(base.path, apply_overrides(base.data, overrides))


def _level_of(scenario: Scenario, level: str | int) -> tuple[int, str]:
    """``(index, name)`` of the stack's level that ``level`` names.

    Raises:
        ConfigurationError: the app names no levels, or none is ``level``.
    """
    stack = tuple(getattr(scenario.app, "stack", None) or ())
    names = [slot.name for slot in stack]
    if not names:
        raise ConfigurationError(
            f"level: {scenario.app.name} declares no stack (a LayerSlot per level): "
            "no level can be learned"
        )
    levels = ", ".join(f"{name} ({index})" for index, name in enumerate(names))
    if isinstance(level, bool) or not isinstance(level, int | str):
        raise ConfigurationError(f"level: expected a level's name or index, got {level!r}")
    if isinstance(level, int):
        if not 0 <= level < len(names):
            raise ConfigurationError(f"level: no level {level}; the stack's levels are {levels}")
        return level, names[level]
    if level not in names:
        raise ConfigurationError(
            f"level: no level named {level!r}; the stack's levels are {levels}"
        )
    return names.index(level), level


def _policy_class(
    scenario: Scenario, level: str, layer: type[PolicyLayer] | None
) -> type[PolicyLayer]:
    """The policy layer's class: ``layer``, or the one the scenario's ``[layers]`` names.

    Raises:
        ConfigurationError: ``layer`` is not a PolicyLayer subclass, or (``None``) the
            scenario names no PolicyLayer for ``level``.
    """
    if layer is None:
        named = scenario.layers.get(level)
        if named is None or not issubclass(named, PolicyLayer):
            built = "the app's own class" if named is None else named.__qualname__
            raise ConfigurationError(
                f"layer: the scenario puts {built} at level {level}, not a PolicyLayer: "
                "pass layer=YourPolicyLayer, or name one in the scenario's [layers]"
            )
        return named
    if not (isinstance(layer, type) and issubclass(layer, PolicyLayer)):
        raise ConfigurationError(
            f"layer: expected a subclass of cas_async.rl.PolicyLayer, got {layer!r}"
        )
    return layer


def _class_path(layer: type[PolicyLayer]) -> str:
    """The ``[layers]`` value that names ``layer``.

    Raises:
        ConfigurationError: ``layer`` is defined inside a function (no path reaches it).
    """
    if "<" in layer.__qualname__:
        raise ConfigurationError(
            f"layer: {layer.__qualname__} is defined inside a function; the scenario's "
            "[layers] imports it by path: define it at module level"
        )
    return f"{layer.__module__}:{layer.__qualname__}"
