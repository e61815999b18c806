"""The layer a policy acts through: :class:`PolicyLayer`, and the seat the env gives each one.

A learnable level is a subclass of the level's own class and of :class:`PolicyLayer`
(``class LearnedPlan(PolicyLayer, Plan)``), put in place by the env through the
scenario's ``[layers]``. Wherever the app's layer would make a choice, the learned
one asks :meth:`PolicyLayer.decide`, which applies the env's ``act`` to the action
its robot holds at that instant; a layer that should do something on every step
(drive one leg, say) overrides :meth:`PolicyLayer.on_action`.

Actions are held (zero-order hold): the action given to ``step()`` is the robot's
from the start of that step until the next step replaces it. A decision the layer
takes at any instant, between two steps or at one, takes the action held then,
at that very instant: virtual time never stops for one robot while the rest of the
swarm goes on, and no decision is moved to a step boundary.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Any, Final, final

from .. import ConfigurationError, Layer

__all__ = ["ACTION_TIMER", "Act", "PolicyLayer", "Seat", "acts_every_step", "bind"]

Act = Callable[[Any, Any, Any], Any]
"""``act(layer, action, context)``: what the layer does, given the held action."""

ACTION_TIMER: Final[Hashable] = ("cas_async.rl", "action")
"""The timer key that tells a layer a new action arrived (see :meth:`PolicyLayer.on_action`)."""


@final
class Seat:
    """One agent's place in the env: the action it holds, and how it turns into decisions.

    Owned by the env; its layer reads it through :class:`PolicyLayer`.

    Args:
        agent: the agent's name (``"robot_3"``), for error messages.
        act: ``act(layer, action, context)``; ``None``: the decision is the action itself.
    """

    __slots__ = ("_act", "_decisions", "_held", "agent")

    def __init__(self, agent: str, act: Act | None) -> None:
        self.agent = agent
        self._act = act
        self._held: Any = None
        self._decisions = 0

    def hold(self, action: Any) -> None:
        """Makes ``action`` the one every decision takes from now on."""
        self._held = action

    @property
    def action(self) -> Any:
        """The action held now (``None`` before the first step)."""
        return self._held

    def decide(self, layer: Layer, context: Any) -> Any:
        """What ``layer`` does now: ``act(layer, action, context)``; counts the decision."""
        self._decisions += 1
        if self._act is None:
            return self._held
        return self._act(layer, self._held, context)

    def take_decisions(self) -> int:
        """Decisions taken since the last call (the env reads it once per step)."""
        taken, self._decisions = self._decisions, 0
        return taken


class PolicyLayer(Layer):
    """Mixin for a level a policy learns: put it first, before the level's class.

    ``class LearnedStrategy(PolicyLayer, TimeStrategy)`` keeps everything of the
    app's layer (its constructor, its protocol with the other robots and levels)
    and replaces the one choice it makes by :meth:`decide`. The scenario's
    ``[layers]`` puts it in place, as it would any other class: the
    :class:`~cas_async.rl.ParallelSwarmEnv` does that itself, with ``layer=``.

    Outside an env it has no actions to take: :meth:`decide` raises.
    """

    _cas_seat: Seat | None = None
    """The env's seat of this layer's robot (every name starting with ``_cas`` is reserved)."""

    def decide(self, context: Any = None) -> Any:
        """What this layer does at this instant: the env's ``act(self, action, context)``.

        ``action`` is the one this robot holds now (the last given to ``step()``),
        ``context`` what the layer knows of the choice (the candidates, where it
        stands). Call it at the instant the app's layer would choose.

        Raises:
            ConfigurationError: the layer runs outside a ``ParallelSwarmEnv``.
        """
        seat = self._cas_seat
        if seat is None:
            raise ConfigurationError(
                f"{type(self).__qualname__} takes its decisions from a policy: run it in a "
                "cas_async.rl.ParallelSwarmEnv (it has no action outside one)"
            )
        return seat.decide(self, context)

    @property
    def current_action(self) -> Any:
        """The action this robot holds now, ``None`` outside an env or before the first step."""
        seat = self._cas_seat
        return None if seat is None else seat.action

    async def on_action(self) -> None:
        """A step gave this robot its action: act on it now, if the layer acts every step.

        Called at the step's first instant, after everything due at the previous
        step's last instant has happened. Only layers that override it are woken:
        the others just read the held action when they :meth:`decide`.
        """

    async def on_timer(self, key: Hashable) -> None:
        """The action timer calls :meth:`on_action`; every other timer is the level's own."""
        if key == ACTION_TIMER:
            await self.on_action()
        else:
            await super().on_timer(key)


def acts_every_step(layer: PolicyLayer) -> bool:
    """Whether ``layer``'s class overrides :meth:`PolicyLayer.on_action`."""
    return type(layer).on_action is not PolicyLayer.on_action


def bind(layer: PolicyLayer, seat: Seat) -> None:
    """Gives ``layer`` its robot's seat (the env does, once the robots are built).

    Raises:
        ConfigurationError: the layer already has a seat (one layer per robot and env).
    """
    if layer._cas_seat is not None:
        raise ConfigurationError(
            f"{type(layer).__qualname__}: this layer already belongs to an env "
            "(create one layer instance per robot)"
        )
    layer._cas_seat = seat
