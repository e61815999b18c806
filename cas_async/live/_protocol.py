"""The view protocol: a JSON hello, then binary frames and JSON events (see ``docs/live.md``).

A viewer opens a WebSocket on the server's ``/ws``. The server sends:

1. a text message, the **hello** (JSON, ``"type": "hello"``): what does not change
   (the world, the robots in frame order, their groups, the scene, the measures'
   names, the mission's target and words);
2. **frames**, binary messages, one per sample sent (see :class:`Frame` for the
   layout): the simulated instant, the sample's index, the progress counts, the
   measures, every robot's position and whether it carries something;
3. text messages of **events** (``"type": "events"``: exchanges, deliveries,
   progress) and, last, ``"type": "end"`` when the run ended.

A replay also answers the viewer's ``{"type": "seek", "t": T}`` with the frame of
the last sample at or before ``T``. Everything is little-endian; positions are
the trace's float64 values, so a frame's positions equal ``trace.csv``'s exactly.
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from ..scenario import Scene
from ._websocket import CloseCode, ProtocolError

__all__ = [
    "CLIENT_DEPTH",
    "FRAME_MAGIC",
    "HEADER",
    "PROTOCOL",
    "PALETTE",
    "UNKNOWN",
    "Frame",
    "colors_for",
    "decode_frame",
    "encode_frame",
    "hello",
    "read_client_message",
    "text",
]

PROTOCOL: Final = 1
"""The protocol's version: in the hello and in every frame."""
FRAME_MAGIC: Final = b"CASF"
UNKNOWN: Final = 0xFFFFFFFF
"""A progress count the sender does not know (a replay's second count, for some apps)."""
HEADER: Final = struct.Struct("<4sHHdIIIIII")
"""magic, version, flags, t, seq, robots, done, detail, measures, reserved: 40 bytes."""
FINAL: Final = 1
"""Frame flag: the last frame of the run."""
PALETTE: Final = (
    "#e69f00", "#0072b2", "#009e73", "#cc79a7", "#56b4e9", "#d55e00", "#8c6d1f", "#6a3d9a",
)  # fmt: skip
"""Colours for groups and scene kinds, in order (Okabe and Ito's, told apart by most eyes)."""
OTHER: Final = "#7f7f7f"
"""The colour of a robot in no group, and of names past the palette."""


def colors_for(groups: Sequence[str], scene: Scene) -> dict[str, str]:
    """One colour per robot group and scene kind: the scene's own, then the palette in order.

    A scene kind named as a group (a Generator's pad) gets the group's colour.
    """
    colors = dict(scene.colors)
    free = [color for color in PALETTE if color not in colors.values()]
    for name in [*groups, *scene.kinds]:
        if name not in colors:
            colors[name] = free.pop(0) if free else OTHER
    return colors


@dataclass(frozen=True, slots=True)
class Frame:
    """One frame, decoded.

    The layout on the wire, in order (little-endian)::

        0   4s   magic "CASF"
        4   u16  protocol version (1)
        6   u16  flags (bit 0: the run's last frame)
        8   f64  t: simulated seconds
        16  u32  seq: the sample's index in the run (0, 1, ...; gaps are skipped frames)
        20  u32  n: robots
        24  u32  done: the objective's count (items delivered, objects moved)
        28  u32  detail: its second count (exchanges, ...); 0xFFFFFFFF unknown
        32  u32  m: measures
        36  u32  reserved (0)
        40  f64 * m        each measure's value (NaN: not known)
        40+8m  f64 * 2n    x, y of each robot, in the hello's robot order
        40+8m+16n  u8 * n  per robot: bit 0 set when it carries something

    Attributes:
        t: simulated instant.
        seq: the sample's index.
        done: the objective's count.
        detail: its second count (``UNKNOWN`` when not known).
        measures: one value per measure named in the hello.
        xy: shape ``(n, 2)``.
        carrying: shape ``(n,)``.
        final: the run's last frame.
    """

    t: float
    seq: int
    done: int
    detail: int
    measures: tuple[float, ...]
    xy: npt.NDArray[np.float64]
    carrying: npt.NDArray[np.bool_]
    final: bool = False


def encode_frame(
    t: float,
    seq: int,
    done: int,
    detail: int,
    measures: tuple[float, ...] | list[float],
    xy: npt.NDArray[np.float64],
    carrying: npt.NDArray[np.bool_],
    *,
    final: bool = False,
) -> bytes:
    """One frame's bytes (see :class:`Frame`)."""
    n = len(xy)
    head = HEADER.pack(
        FRAME_MAGIC,
        PROTOCOL,
        FINAL if final else 0,
        t,
        seq & 0xFFFFFFFF,
        n,
        min(max(done, 0), UNKNOWN),
        min(max(detail, 0), UNKNOWN),
        len(measures),
        0,
    )
    values = struct.pack(f"<{len(measures)}d", *measures)
    positions = np.ascontiguousarray(xy, dtype="<f8").tobytes()
    flags = np.asarray(carrying, dtype=np.uint8).tobytes()
    return b"".join((head, values, positions, flags))


def decode_frame(data: bytes) -> Frame:
    """Reads one frame (what a Python viewer does); see :class:`Frame`.

    Raises:
        ValueError: not a frame of this protocol, or its length does not add up.
    """
    if len(data) < HEADER.size:
        raise ValueError(f"frame: {len(data)} bytes, shorter than its {HEADER.size}-byte header")
    magic, version, flags, t, seq, n, done, detail, m, _ = HEADER.unpack_from(data)
    if magic != FRAME_MAGIC or version != PROTOCOL:
        raise ValueError(f"frame: magic {magic!r} version {version}, expected {FRAME_MAGIC!r} 1")
    expected = HEADER.size + 8 * m + 17 * n
    if len(data) != expected:
        raise ValueError(
            f"frame: {len(data)} bytes, expected {expected} for {n} robots, {m} measures"
        )
    at = HEADER.size
    measures = struct.unpack_from(f"<{m}d", data, at)
    at += 8 * m
    xy = np.frombuffer(data, dtype="<f8", count=2 * n, offset=at).reshape(n, 2).astype(np.float64)
    at += 16 * n
    carrying = np.frombuffer(data, dtype=np.uint8, count=n, offset=at) & 1 == 1
    return Frame(t, seq, done, detail, measures, xy, carrying, final=bool(flags & FINAL))


def hello(
    mode: str,
    *,
    app: str,
    scenario: str,
    seed: int,
    world: tuple[float, float],
    robots: Sequence[int],
    groups: Mapping[str, Sequence[int]],
    scene: Scene,
    measures: Sequence[str],
    target: int,
    words: tuple[str, str, str],
    kind: str,
    **more: Any,
) -> dict[str, Any]:
    """The hello: what a viewer needs before the first frame (see ``docs/live.md``).

    ``mode`` is ``"live"`` or ``"replay"``; ``words`` are the objective's noun,
    verb and second count's name (``"bucket"``, ``"delivered"``, ``"exchanges"``);
    ``kind`` is the objective's (``"items"``: exchange and delivered events name
    the robots and items); ``more`` adds mode-specific keys (``fps``, ``pace``; a
    replay's ``times``, ``events``, ``end``).
    """
    noun, verb, detail = words
    return {
        "type": "hello",
        "protocol": PROTOCOL,
        "mode": mode,
        "app": app,
        "scenario": scenario,
        "seed": seed,
        "world": {"width": world[0], "height": world[1]},
        "robots": [int(robot) for robot in robots],
        "groups": [{"name": name, "robots": [int(r) for r in ids]} for name, ids in groups.items()],
        "scene": scene.to_json(),
        "colors": colors_for(list(groups), scene),
        "measures": list(measures),
        "target": target,
        "kind": kind,
        "noun": noun,
        "verb": verb,
        "detail": detail,
        **more,
    }


def text(message: dict[str, Any]) -> str:
    """A JSON text message: compact, no NaN or infinity (they become ``null``)."""
    try:
        return json.dumps(message, separators=(",", ":"), allow_nan=False)
    except ValueError:  # a NaN or an infinity somewhere: rare, so looked for only now
        return json.dumps(_finite(message), separators=(",", ":"), allow_nan=False)


def _finite(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {key: _finite(item) for key, item in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(item) for item in value]
    return value


CLIENT_DEPTH: Final = 8
"""Nesting of a viewer's JSON message, at most (a seek is 1 deep)."""


def read_client_message(text: str) -> dict[str, Any] | None:
    """A viewer's text message as a JSON object; ``None`` if it is no JSON object.

    The message is at most :data:`~cas_async.live._connection.MESSAGE_LIMIT` bytes
    (the frame reader refuses longer ones, 1009); its nesting is counted before it
    is parsed, so no message costs more than a pass over its characters.

    Raises:
        ProtocolError: nested deeper than :data:`CLIENT_DEPTH` (close 1008).
    """
    if _depth(text) > CLIENT_DEPTH:
        raise ProtocolError(
            CloseCode.POLICY_VIOLATION, f"a message nested deeper than {CLIENT_DEPTH}"
        )
    try:
        message = json.loads(text)
    except (ValueError, RecursionError):  # not JSON (or its numbers too long): ignored
        return None
    return message if isinstance(message, dict) else None


def _depth(text: str) -> int:
    """How deep ``[`` and ``{`` nest in ``text``, outside JSON strings."""
    depth = deepest = 0
    inside = escaped = False
    for char in text:
        if inside:
            if escaped:
                escaped = False
            elif char == "\\":
                escaped = True
            elif char == '"':
                inside = False
        elif char == '"':
            inside = True
        elif char in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif char in "]}":
            depth -= 1
    return deepest
