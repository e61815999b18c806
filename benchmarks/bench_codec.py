"""Codec: encode + decode per second of one typical message, no sockets.

Framework: ``Codec.decode(Codec.encode(msg))`` for a ``Sample`` (header, 2 floats,
an int, a bool, a short str, 10 ints), which reads the object, packs it and builds
a new checked ``Sample``. Baseline: ``msgpack.unpackb(msgpack.packb(values))`` of
the equivalent plain list (the same 8 header ints and 6 fields, the same bytes).
Timed with ``time.perf_counter`` over ``size`` iterations. The event loop plays
no part; it is run on each loop only to give one result line per loop.

Target: framework / baseline >= 0.8.
"""

from __future__ import annotations

import sys
import time

import msgpack

from cas_async._message import specs_for
from cas_async.transport import Codec, stack_fingerprint

from ._common import MESSAGES, Bench, main, raw_sample, sample

LEVELS = 5


def make_codec() -> Codec:
    specs = specs_for(MESSAGES)
    return Codec(specs, stack_fingerprint(LEVELS, specs))


async def framework(iterations: int) -> float:
    codec = make_codec()
    encode, decode = codec.encode, codec.decode
    msg = sample(7)
    msg.msg_id, msg.robot_id = 7, 1  # the header raw_sample(7) carries
    assert decode(encode(msg)) == msg
    assert len(encode(msg)) == len(msgpack.packb(raw_sample(7)))
    started = time.perf_counter()
    for _ in range(iterations):
        decode(encode(msg))
    return iterations / (time.perf_counter() - started)


async def baseline(iterations: int) -> float:
    packb, unpackb = msgpack.packb, msgpack.unpackb
    values = raw_sample(7)
    assert unpackb(packb(values)) == values
    started = time.perf_counter()
    for _ in range(iterations):
        unpackb(packb(values))
    return iterations / (time.perf_counter() - started)


BENCHES = [
    Bench(
        name="codec",
        unit="ops/s",
        framework=framework,
        baseline=baseline,
        size=300_000,
        quick_size=30_000,
        target=0.8,
    )
]

if __name__ == "__main__":
    sys.exit(main(BENCHES))
