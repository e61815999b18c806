"""Benchmarks of cas_async against hand-written asyncio, run in the same process.

``python -m benchmarks`` runs them all (``--quick``, ``--runs N``,
``--loop stdlib|uvloop|both``, ``--only NAME``); ``python -m benchmarks.bench_codec``
and the like run one file. Each benchmark prints a table row and one JSON line per
loop; the exit status is 1 when a target is missed.
"""
