"""Codec: encode + decode per second of one typical message, no sockets.

Framework: ``Codec.decode(Codec.encode(msg))`` for a ``Sample`` (header, 2 floats,
an int, a bool, a short str, 10 ints), which reads the object, packs it and builds
a new checked ``Sample``. Baseline: ``msgpack.unpackb(msgpack.packb(values))`` of
the equivalent plain list (the same 8 header ints and 6 fields, the same bytes).
Timed with ``time.perf_counter`` over ``size`` iterations. The event loop plays
no part; it is run on each loop only to give one result line per loop.

Target: framework / baseline >= 0.8.

``codec_hostile``: decoding what a stranger sends, against decoding what a robot
sends. Framework: ``Codec.decode`` of hostile datagrams of about 60 KB, each
refused (``DecodeError``), in turn: arrays nested 499 deep in a ``list[int]`` field
and in a ``float`` field, 60,000 empty arrays, nils or empty maps where ints belong,
and a body that is one long array instead of a message. Baseline: ``Codec.decode``
of a well-formed datagram of the same size (a ``Sample`` whose ``values`` hold
60,000 ints). Figures are datagrams decoded per second. Target: framework /
baseline >= 0.5: a hostile datagram costs at most twice what a well-formed one of
its size does (msgpack's pure-Python unpacker, which such arrays used to reach,
took 15-23 ms for one).
"""

from __future__ import annotations

import struct
import sys
import time

import msgpack

from cas_async import DecodeError
from cas_async._message import specs_for
from cas_async.transport import Codec, stack_fingerprint

from ._common import MESSAGES, Bench, Sample, main, raw_sample, sample

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


HOSTILE_SIZE = 60_000  # bytes of payload: a datagram of about 60 KB, under the 64 KB maximum


def _encoded(codec: Codec, values: list[int]) -> bytes:
    msg = Sample(1.5, -2.25, 7, True, "robot-7", values)
    msg.msg_id, msg.robot_id = 7, 1
    return codec.encode(msg)


def hostile_datagrams(codec: Codec) -> list[bytes]:
    """Datagrams of about 60 KB that the codec must refuse, of the costliest shapes known."""
    fields = msgpack.unpackb(_encoded(codec, []))
    header = msgpack.packb(fields[:8])[1:]  # fingerprint, type id, header; no array head
    packed = [msgpack.packb(value) for value in fields[8:]]  # x, y, n, ok, name, values

    def body(*field_bytes: bytes) -> bytes:
        return bytes([0x90 + 8 + len(field_bytes)]) + header + b"".join(field_bytes)

    def array(items: bytes, count: int) -> bytes:
        return b"\xdc" + struct.pack(">H", count) + items * count

    chain = b"\x91" * 499 + b"\x00"  # nested as deep as a field may be
    chains = array(chain, HOSTILE_SIZE // len(chain))
    return [
        body(*packed[:5], chains),
        body(chains, *packed[1:]),
        body(*packed[:5], array(b"\x90", HOSTILE_SIZE)),
        body(*packed[:5], array(b"\xc0", HOSTILE_SIZE)),
        body(*packed[:5], array(b"\x80", HOSTILE_SIZE)),
        array(b"\x00", HOSTILE_SIZE),
    ]


async def hostile(iterations: int) -> float:
    decode = make_codec().decode
    datagrams = hostile_datagrams(make_codec())
    for data in datagrams:
        try:
            decode(data)
        except DecodeError:
            continue
        raise AssertionError("a hostile datagram was accepted")
    rounds = max(1, iterations // len(datagrams))
    started = time.perf_counter()
    for _ in range(rounds):
        for data in datagrams:
            try:  # noqa: SIM105 (contextlib.suppress would cost more than some decodes)
                decode(data)
            except DecodeError:
                pass
    return rounds * len(datagrams) / (time.perf_counter() - started)


async def well_formed(iterations: int) -> float:
    codec = make_codec()
    decode = codec.decode
    data = _encoded(codec, [1] * HOSTILE_SIZE)
    assert abs(len(data) - len(hostile_datagrams(codec)[0])) < 100  # the same size
    started = time.perf_counter()
    for _ in range(iterations):
        decode(data)
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
    ),
    Bench(
        name="codec_hostile",
        unit="datagrams/s",
        framework=hostile,
        baseline=well_formed,
        size=3_000,
        quick_size=300,
        target=0.5,
    ),
]

if __name__ == "__main__":
    sys.exit(main(BENCHES))
