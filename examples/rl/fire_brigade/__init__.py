"""The Fire Brigade with a learned Strategy layer: which robot in range to ask first, or none.

* :mod:`.layer`: ``LearnedStrategy``, the time strategy whose first choice a policy makes;
* :mod:`.env`: the environment (observation, reward, action), ``make_env()``;
* :mod:`.baseline`: a random policy against the built-in choice over a few seeds
  (``python -m examples.rl.fire_brigade.baseline``).
"""

__all__: list[str] = []
