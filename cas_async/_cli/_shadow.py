"""The clone's folder taken for the package: ``import cas_async`` from the folder above it.

A clone of the repository is a folder named ``cas_async`` holding the package
``cas_async/``. Python run from the folder that contains the clone finds the clone
first on its path; a folder without ``__init__.py`` is a namespace package, and
an editable install (``pip install -e``) is consulted only after the path. The
clone then becomes ``cas_async``, empty: ``module 'cas_async' has no attribute
'Layer'``. The package's ``__init__`` never runs there, so nothing in it can
tell; what runs is ``python -m cas_async`` (its ``__main__``, found through the
editable install) and the pytest plugin, and both check with :func:`shadowed`.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

__all__ = ["explain", "shadowed"]


def shadowed() -> Path | None:
    """The folder that ``cas_async`` resolves to when it is no package, else ``None``.

    Looks at the module imported (``sys.modules``) or, before any import, at what
    an import would find: a regular package has an ``__init__.py``; a namespace
    package has none (its spec's ``origin`` is ``None``).
    """
    module = sys.modules.get("cas_async")
    spec = module.__spec__ if module is not None else importlib.util.find_spec("cas_async")
    if spec is None or spec.origin is not None or not spec.submodule_search_locations:
        return None
    return Path(next(iter(spec.submodule_search_locations)))


def explain(folder: Path) -> str:
    """What happened, and what to do, in a few lines."""
    return (
        f"cas_async is the folder {folder}, not the package: that folder has no __init__.py "
        "(a clone of the repository, seen from the folder that contains it), so Python "
        "imported it as an empty namespace package and nothing of cas_async is in it "
        "(module 'cas_async' has no attribute 'Layer'). Run Python from inside the clone "
        f"(cd {folder}) or from any folder but {folder.parent}, or install the package "
        "without -e (pip install ./cas_async)."
    )
