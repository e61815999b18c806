"""``python -m cas_async.ros``: see :mod:`cas_async.ros._command`."""

import sys

from ._command import main

__all__: list[str] = []

if __name__ == "__main__":
    sys.exit(main())
