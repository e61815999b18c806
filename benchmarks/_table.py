"""One aligned text table, as every benchmark prints it (no imports: any benchmark may use it)."""

from __future__ import annotations

from collections.abc import Collection, Sequence


def print_aligned(lines: Sequence[Sequence[str]], left: Collection[int] = ()) -> None:
    """Prints ``lines`` (the header first) in columns, with a rule under the header.

    Columns whose index is in ``left`` are aligned left (names); the rest right (numbers).
    """
    widths = [max(map(len, column)) for column in zip(*lines, strict=True)]
    for i, line in enumerate(lines):
        pairs = enumerate(zip(line, widths, strict=True))
        print("  ".join(c.ljust(w) if j in left else c.rjust(w) for j, (c, w) in pairs))
        if i == 0:
            print("  ".join("-" * w for w in widths))
