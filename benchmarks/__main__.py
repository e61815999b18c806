"""Runs every benchmark: ``python -m benchmarks [--quick] [--runs N] [--loop ...] [--only NAME]``.

The mango-agents comparisons need the ``bench`` extra (``pip install -e ".[bench]"``),
the Zenoh ones (cas_async on Zenoh against raw Zenoh) the ``zenoh`` extra
(``pip install -e ".[zenoh]"``); without them they are skipped, and said so.
"""

import sys

from . import (
    bench_codec,
    bench_external,
    bench_internal,
    bench_mango,
    bench_processes,
    bench_zenoh,
)
from ._common import main

if not bench_mango.available():
    print(bench_mango.skip_message(), file=sys.stderr)
if not bench_zenoh.available():
    print(bench_zenoh.skip_message(), file=sys.stderr)
sys.exit(
    main(
        [
            *bench_internal.BENCHES,
            *bench_external.BENCHES,
            *bench_processes.BENCHES,
            *bench_codec.BENCHES,
            *bench_mango.BENCHES,
            *bench_zenoh.BENCHES,
        ]
    )
)
