"""``python -m cas_async``: see :mod:`cas_async._cli._main`."""

import sys

from ._cli._interrupts import exit_on_signal
from ._cli._shadow import explain, shadowed

__all__: list[str] = []

if __name__ == "__main__":
    # Before the imports that take time (importing cas_async itself took almost none):
    # a signal now exits 130 quietly, until the command line takes over.
    exit_on_signal()
    folder = shadowed()  # the package itself never ran: see cas_async._cli._shadow
    if folder is not None:
        print(f"error: {explain(folder)}", file=sys.stderr)
        sys.exit(2)
    from ._cli._main import main

    sys.exit(main(owns_process=True))
