"""``python -m cas_async``: see :mod:`cas_async._cli`."""

import sys

from ._cli import main

__all__: list[str] = []

if __name__ == "__main__":
    sys.exit(main(owns_process=True))
