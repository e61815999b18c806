"""``python -m cas_async``: see :mod:`cas_async.cli`."""

import sys

from .cli import main

__all__: list[str] = []

if __name__ == "__main__":
    sys.exit(main())
