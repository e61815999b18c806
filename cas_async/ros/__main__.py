"""``python -m cas_async.ros``: see :mod:`cas_async.ros._cli`."""

import sys

from ._cli import main

__all__: list[str] = []

if __name__ == "__main__":
    sys.exit(main())
