"""Learning a layer: a scenario as a PettingZoo environment on virtual time.

Needs the ``rl`` extra (``pip install "cas_async[rl]"``: pettingzoo and gymnasium).

* :class:`ParallelSwarmEnv`: a scenario as a PettingZoo ``ParallelEnv``. Agents are
  robots; the policy acts through one level of their stack, which the env replaces
  by a :class:`PolicyLayer` through the scenario's ``[layers]``; every other level
  runs as the app wrote it. Each ``step`` advances virtual time by exactly ``dt``.
* :class:`PolicyLayer`: the mixin of a learnable level
  (``class LearnedPlan(PolicyLayer, Plan)``): :meth:`PolicyLayer.decide` where the
  app's layer would choose, :meth:`PolicyLayer.on_action` to act on every step.
* :class:`StepOutcome`: what a step did, for the reward function.
* :class:`EpisodeFailed`: a layer raised during a step.

See docs/rl.md for the guide: how a layer becomes learnable, what virtual time
guarantees per step, and the ready environments of ``examples/rl``.
"""

try:
    import gymnasium as _gymnasium  # noqa: F401 - checked here, to say what to install
    import pettingzoo as _pettingzoo  # noqa: F401
except ImportError as error:  # pragma: no cover - depends on the installed extras
    raise ImportError(
        f'cas_async.rl needs the rl extra ({error.name} is missing): pip install "cas_async[rl]"'
    ) from error

from ._env import ParallelSwarmEnv
from ._episode import EpisodeFailed, StepOutcome
from ._policy import PolicyLayer

__all__ = ["EpisodeFailed", "ParallelSwarmEnv", "PolicyLayer", "StepOutcome"]
