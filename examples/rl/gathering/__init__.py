"""The gathering with a learned Plan layer: each step, each robot drives one leg or stays.

* :mod:`.layer`: ``LearnedPlan``, the tutorial's ``Plan`` whose moves a policy makes;
* :mod:`.env`: the environment (observation, reward, action), ``make_env()``;
* :mod:`.baseline`: a random policy over a few seeds (``python -m examples.rl.gathering.baseline``);
* :mod:`.train`: REINFORCE in numpy, with its learning curve
  (``python -m examples.rl.gathering.train``).
"""

__all__: list[str] = []
