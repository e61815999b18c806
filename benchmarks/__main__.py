"""Runs every benchmark: ``python -m benchmarks [--quick] [--runs N] [--loop ...]``."""

import sys

from . import bench_codec, bench_external, bench_internal
from ._common import main

sys.exit(main([*bench_internal.BENCHES, *bench_external.BENCHES, *bench_codec.BENCHES]))
