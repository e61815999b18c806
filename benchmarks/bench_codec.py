"""Codec: encode + decode per second of typical messages, no sockets.

``codec``: ``Codec.decode(Codec.encode(msg))`` of a ``Sample`` (2 floats, an int,
a bool, a short str, 10 ints, and the header), which reads the object, packs it
and builds a new checked ``Sample``. Baseline: ``msgpack.unpackb(msgpack.packb(values))``
of the equivalent plain list (the same tag, fields and header: the same bytes but
the fingerprint). Target: framework / baseline >= 0.8.

``codec_<Message>``: the same for each external message of the Fire Brigade, with
the values it typically carries (the header stamped as a robot stamps it). Target:
framework / baseline >= 1.0: a typed, checked message costs less than msgpack
packing and unpacking a plain list of its values.

Timed with ``time.perf_counter`` over ``size`` iterations. The event loop plays no
part; it is run on each loop only to give one result line per loop.

``codec_hostile``: decoding what a stranger sends, against decoding what a robot
sends. Framework: ``Codec.decode`` of hostile datagrams of about 60 KB, each
refused (``DecodeError``), in turn: arrays nested 499 deep in a ``list[int]`` field
and in a ``float`` field, 60,000 empty arrays, nils or empty maps where ints belong,
and a body that is one long array instead of a message. Baseline: ``Codec.decode``
of a well-formed datagram of the same size (a ``Sample`` whose ``values`` hold
60,000 ints). Figures are datagrams decoded per second. Target: framework /
baseline >= 0.5: a hostile datagram costs at most twice what a well-formed one of
its size does.
"""

from __future__ import annotations

import struct
import sys
import time
from collections.abc import Callable

import msgpack

from apps.fire_brigade.messages import (
    MESSAGES as BRIGADE,
)
from apps.fire_brigade.messages import (
    Destination,
    Handover,
    Kind,
    Meet,
    Meeting,
    MeetingPoint,
    PartnerAnswer,
    RequestInfo,
    RequestPartner,
    RobotInfo,
)
from cas_async import DecodeError, Message, MsgType
from cas_async.transport import Codec

from ._common import MESSAGES, PREFIX, Bench, Measure, Sample, main, sample

LEVELS = 5
ROBOT, LEVEL = 7, 1
MSG_ID = 1_764_000_000_123_456  # ids count microseconds of the clock: this is a typical one


def make_codec(messages: list[type[Message]] | tuple[type[Message], ...] = MESSAGES) -> Codec:
    return Codec(LEVELS, messages)


def stamped(msg: Message, corr_id: int = 0) -> Message:
    """``msg`` with the header a robot writes when it sends it from level ``LEVEL``."""
    msg.msg_id, msg.robot_id, msg.src_layer, msg.dst_layer = MSG_ID, ROBOT, LEVEL, LEVEL
    msg.corr_id = corr_id
    return msg


def round_trips(codec: Codec, msg: Message) -> tuple[Measure, Measure]:
    """The framework and baseline measurements of one message's encode + decode."""
    encode, decode = codec.encode, codec.decode
    values = msgpack.unpackb(encode(msg)[PREFIX:])  # the same values, as a plain list
    assert decode(encode(msg)) == msg
    assert msgpack.packb(values) == encode(msg)[PREFIX:]  # the very same bytes

    async def framework(iterations: int) -> float:
        started = time.perf_counter()
        for _ in range(iterations):
            decode(encode(msg))
        return iterations / (time.perf_counter() - started)

    async def baseline(iterations: int) -> float:
        packb, unpackb = msgpack.packb, msgpack.unpackb
        started = time.perf_counter()
        for _ in range(iterations):
            unpackb(packb(values))
        return iterations / (time.perf_counter() - started)

    return framework, baseline


def brigade_messages() -> list[Message]:
    """Each external message of the Fire Brigade, with typical values, as a robot sends it."""
    to = Destination(2, 5.0, 19.0)
    return [
        stamped(RequestInfo(msg_type=MsgType.NEGOTIATION)),
        stamped(RobotInfo(3.25, 7.5, Kind.TRANSPORTER, 1.2), corr_id=MSG_ID - 9),
        stamped(RequestPartner(3.5, 4.25, Kind.TRANSPORTER, 17, to, msg_type=MsgType.NEGOTIATION)),
        stamped(PartnerAnswer(Kind.TRANSPORTER), corr_id=MSG_ID - 9),
        stamped(Meet(3.5, 4.25, Kind.TRANSPORTER, 0.8, MSG_ID - 99, msg_type=MsgType.NEGOTIATION)),
        stamped(MeetingPoint(4.0, 4.5, MSG_ID - 99), corr_id=MSG_ID - 9),
        stamped(Meeting(MSG_ID - 99, msg_type=MsgType.NEGOTIATION)),
        stamped(Handover(17, MSG_ID - 99)),
    ]


def _bench(name: str, measures: Callable[[], tuple[Measure, Measure]], target: float) -> Bench:
    framework_of: list[Measure] = []

    def built() -> tuple[Measure, Measure]:
        if not framework_of:
            framework_of.extend(measures())
        return framework_of[0], framework_of[1]

    async def framework(size: int) -> float:
        return await built()[0](size)

    async def baseline(size: int) -> float:
        return await built()[1](size)

    return Bench(name, "ops/s", framework, baseline, 300_000, 30_000, target)


def _sample_round_trips() -> tuple[Measure, Measure]:
    return round_trips(make_codec(), stamped(sample(7)))


def _brigade_round_trips(index: int) -> Callable[[], tuple[Measure, Measure]]:
    return lambda: round_trips(make_codec(BRIGADE), brigade_messages()[index])


HOSTILE_SIZE = 60_000  # bytes of payload: a datagram of about 60 KB, under the 64 KB maximum


def _encoded(codec: Codec, values: list[int]) -> bytes:
    return codec.encode(stamped(Sample(1.5, -2.25, 7, True, "robot-7", values)))


def hostile_datagrams(codec: Codec) -> list[bytes]:
    """Datagrams of about 60 KB that the codec must refuse, of the costliest shapes known."""
    items = msgpack.unpackb(_encoded(codec, [])[PREFIX:])
    tag = msgpack.packb(items[0])
    fields = [msgpack.packb(value) for value in items[1:7]]  # x, y, n, ok, name, values
    header = b"".join(msgpack.packb(value) for value in items[7:])

    def body(*field_bytes: bytes) -> bytes:
        count = 1 + len(field_bytes) + len(items) - 7
        return (
            codec.fingerprint.to_bytes(PREFIX, "big")
            + bytes([0x90 + count])
            + tag
            + (b"".join(field_bytes) + header)
        )

    def array(element: bytes, count: int) -> bytes:
        return b"\xdc" + struct.pack(">H", count) + element * count

    chain = b"\x91" * 499 + b"\x00"  # nested as deep as a field may be
    chains = array(chain, HOSTILE_SIZE // len(chain))
    prefix = codec.fingerprint.to_bytes(PREFIX, "big")
    return [
        body(*fields[:5], chains),
        body(chains, *fields[1:]),
        body(*fields[:5], array(b"\x90", HOSTILE_SIZE)),
        body(*fields[:5], array(b"\xc0", HOSTILE_SIZE)),
        body(*fields[:5], array(b"\x80", HOSTILE_SIZE)),
        prefix + array(b"\x00", HOSTILE_SIZE),
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
    _bench("codec", _sample_round_trips, 0.8),
    *(
        _bench(f"codec_{type(msg).__name__}", _brigade_round_trips(index), 1.0)
        for index, msg in enumerate(brigade_messages())
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
