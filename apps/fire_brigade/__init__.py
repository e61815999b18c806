"""The Fire Brigade of thesis chapter 5, on cas_async: see this directory's README.

``app`` is what a scenario file names (``app = "apps.fire_brigade"``). To try your
own partner selection, subclass :class:`Strategy`, override ``choose``, and name it
in the scenario: ``[strategy] name = "my_module:MyStrategy"``.
"""

from .app import MESSAGES, FireBrigade
from .messages import Kind
from .strategies import (
    RandomStrategy,
    SinkFirstStrategy,
    SoloStrategy,
    TimeGainStrategy,
    TimeStrategy,
)
from .strategy import Candidate, SearchView, Strategy

__all__ = [
    "MESSAGES",
    "Candidate",
    "FireBrigade",
    "Kind",
    "RandomStrategy",
    "SearchView",
    "SinkFirstStrategy",
    "SoloStrategy",
    "Strategy",
    "TimeGainStrategy",
    "TimeStrategy",
    "app",
]

app = FireBrigade()
"""The app object the scenario runner loads."""
