"""``python -m cas_async``: see :mod:`cas_async._cli`."""

import sys

from ._shadow import explain, shadowed

__all__: list[str] = []

if __name__ == "__main__":
    folder = shadowed()  # the package itself never ran: see cas_async._shadow
    if folder is not None:
        print(f"error: {explain(folder)}", file=sys.stderr)
        sys.exit(2)
    from ._cli import main

    sys.exit(main(owns_process=True))
