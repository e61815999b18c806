"""Two scenarios as PettingZoo environments, with a level learned (see docs/rl.md).

* :mod:`.gathering`: the tutorial's gathering, its Plan layer learned (where to drive,
  leg by leg), with a random baseline and a REINFORCE training in numpy;
* :mod:`.fire_brigade`: the Fire Brigade, its Strategy layer learned (which robot in
  range to ask for the bucket first, or none), with a random baseline.

They need the ``rl`` extra: ``pip install -e ".[rl]"``.
"""

__all__: list[str] = []
