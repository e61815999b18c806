"""The server side of RFC 6455 (WebSocket), as much of it as a view needs: no extensions.

:func:`accept_key` answers the opening handshake; :func:`frame` builds the
server's unmasked frames (each message in one frame); :class:`FrameReader` reads
the client's frames as they arrive, in any pieces, and turns them into whole
messages, refusing what the RFC forbids with the close code it names:

* a frame that is not masked, or has RSV bits set (no extension was agreed),
  an unknown opcode, a fragmented or long control frame, a continuation
  without a start, or a new message inside a fragmented one: 1002;
* a message longer than the reader's limit: 1009;
* a text message that is not UTF-8: 1007.

Why a server of our own rather than a package: see ``docs/live.md`` ("Why a
WebSocket server of its own"): in short, every timer of a general-purpose
implementation runs on the loop's clock, which is virtual during a virtual run.
"""

from __future__ import annotations

import base64
import enum
import hashlib
import struct
from dataclasses import dataclass
from typing import Final

__all__ = ["CloseCode", "FrameReader", "Message", "Opcode", "ProtocolError", "accept_key", "frame"]

_GUID: Final = b"258EAFA5-E914-47DA-95CA-C5AB0DC85B11"  # RFC 6455, section 1.3


class Opcode(enum.IntEnum):
    """The frame opcodes of RFC 6455, section 5.2."""

    CONTINUATION = 0x0
    TEXT = 0x1
    BINARY = 0x2
    CLOSE = 0x8
    PING = 0x9
    PONG = 0xA


class CloseCode(enum.IntEnum):
    """The close codes used here (RFC 6455, section 7.4.1)."""

    NORMAL = 1000
    GOING_AWAY = 1001
    PROTOCOL_ERROR = 1002
    UNSUPPORTED = 1003
    INVALID_DATA = 1007
    POLICY_VIOLATION = 1008
    TOO_BIG = 1009
    INTERNAL_ERROR = 1011


class ProtocolError(Exception):
    """The client broke the protocol: the connection closes with :attr:`code`."""

    def __init__(self, code: CloseCode, reason: str) -> None:
        super().__init__(f"{reason} (close {int(code)})")
        self.code = code
        self.reason = reason


@dataclass(frozen=True, slots=True)
class Message:
    """A whole message from the client: a data message or a control frame."""

    opcode: Opcode
    payload: bytes


def accept_key(key: str) -> str:
    """The ``Sec-WebSocket-Accept`` value for the client's ``Sec-WebSocket-Key``.

    Raises:
        ValueError: the key is not 16 bytes in base64 (RFC 6455, section 4.2.1).
    """
    try:
        raw = base64.b64decode(key.encode("ascii"), validate=True)
    except (ValueError, UnicodeEncodeError):
        raw = b""
    if len(raw) != 16:
        raise ValueError(f"Sec-WebSocket-Key must be 16 bytes in base64, got {key!r:.40}")
    digest = hashlib.sha1(key.encode("ascii") + _GUID).digest()
    return base64.b64encode(digest).decode("ascii")


def frame(opcode: Opcode, payload: bytes) -> bytes:
    """One final, unmasked frame (a server's frames are never masked)."""
    n = len(payload)
    first = 0x80 | int(opcode)
    if n < 126:
        head = struct.pack("!BB", first, n)
    elif n < 1 << 16:
        head = struct.pack("!BBH", first, 126, n)
    else:
        head = struct.pack("!BBQ", first, 127, n)
    return head + payload


def close_payload(code: CloseCode, reason: str = "") -> bytes:
    """A close frame's payload: the code, then the reason (at most 123 bytes of UTF-8)."""
    return struct.pack("!H", int(code)) + reason.encode("utf-8")[:123]


class FrameReader:
    """Reads the client's frames from bytes as they come; yields whole messages.

    Args:
        limit: the largest message accepted, in bytes (1009 beyond).
    """

    def __init__(self, limit: int) -> None:
        self._limit = limit
        self._buffer = bytearray()
        self._parts: list[bytes] = []  # a fragmented message's frames so far
        self._opcode: Opcode | None = None  # and its opcode
        self._size = 0

    def feed(self, data: bytes) -> list[Message]:
        """Adds ``data``; returns the messages now whole (control frames as they come).

        Raises:
            ProtocolError: the client broke the protocol (see the module docs).
        """
        self._buffer += data
        messages: list[Message] = []
        while True:
            read = self._frame()
            if read is None:
                return messages
            fin, opcode, payload = read
            if opcode >= Opcode.CLOSE:
                messages.append(Message(opcode, payload))
                continue
            if opcode is Opcode.CONTINUATION:
                if self._opcode is None:
                    raise ProtocolError(CloseCode.PROTOCOL_ERROR, "continuation without a start")
            elif self._opcode is not None:
                raise ProtocolError(CloseCode.PROTOCOL_ERROR, "new message inside a fragmented one")
            else:
                self._opcode = opcode
            self._parts.append(payload)
            if fin:
                whole = b"".join(self._parts)
                kind, self._opcode, self._parts, self._size = self._opcode, None, [], 0
                if kind is Opcode.TEXT:
                    try:
                        whole.decode("utf-8")
                    except UnicodeDecodeError:
                        raise ProtocolError(CloseCode.INVALID_DATA, "text is not UTF-8") from None
                messages.append(Message(kind, whole))

    def _frame(self) -> tuple[bool, Opcode, bytes] | None:
        """The next whole frame, unmasked, or ``None`` until more bytes come."""
        buffer = self._buffer
        if len(buffer) < 2:
            return None
        first, second = buffer[0], buffer[1]
        if first & 0x70:
            raise ProtocolError(CloseCode.PROTOCOL_ERROR, "RSV bits set: no extension was agreed")
        try:
            opcode = Opcode(first & 0x0F)
        except ValueError:
            raise ProtocolError(
                CloseCode.PROTOCOL_ERROR, f"unknown opcode {first & 0x0F}"
            ) from None
        fin = bool(first & 0x80)
        if not second & 0x80:
            raise ProtocolError(CloseCode.PROTOCOL_ERROR, "a client's frames must be masked")
        length, at = second & 0x7F, 2
        if opcode >= Opcode.CLOSE and (length > 125 or not fin):
            raise ProtocolError(CloseCode.PROTOCOL_ERROR, "a control frame must be short and whole")
        if length == 126:
            if len(buffer) < 4:
                return None
            (length,), at = struct.unpack_from("!H", buffer, 2), 4
        elif length == 127:
            if len(buffer) < 10:
                return None
            (length,), at = struct.unpack_from("!Q", buffer, 2), 10
        if opcode < Opcode.CLOSE and self._size + length > self._limit:
            raise ProtocolError(CloseCode.TOO_BIG, f"message over {self._limit} bytes")
        end = at + 4 + length
        if len(buffer) < end:
            return None
        mask = bytes(buffer[at : at + 4])
        payload = _unmask(bytes(buffer[at + 4 : end]), mask)
        del buffer[:end]
        if opcode < Opcode.CLOSE:
            self._size += length
        return fin, opcode, payload


def _unmask(data: bytes, mask: bytes) -> bytes:
    """XORs ``data`` with the 4-byte ``mask`` repeated (whole-integer arithmetic: no loop)."""
    if not data:
        return data
    repeated = (mask * (len(data) // 4 + 1))[: len(data)]
    value = int.from_bytes(data, "big") ^ int.from_bytes(repeated, "big")
    return value.to_bytes(len(data), "big")
