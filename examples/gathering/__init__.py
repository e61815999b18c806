"""A tutorial app: robots scattered in a world agree on a meeting point and drive there.

* :mod:`.messages`: the typed messages;
* :mod:`.plan`, :mod:`.drive`: the two layers, one file each;
* :mod:`.objective`: when the mission is done, and what it measured;
* :mod:`.app`: the scenario app (settings, checks, building the swarm).

Run it with ``python -m cas_async run examples/gathering/gathering.toml``; see
README.md beside this file.
"""

__all__: list[str] = []  # import from the modules: ``from examples.gathering.app import app``
