"""One open WebSocket of the view: what the server sends to one page, and how it holds back.

Frames go out while the connection's buffer is below its high-water mark; past it
(a viewer that reads slowly, or not at all) each new frame replaces the one
waiting, and only the latest is sent when the buffer drains (latest frame wins).
Text messages (events) wait in a bounded queue, the oldest dropped first and
counted.
"""

from __future__ import annotations

import asyncio
from collections import deque
from typing import Final, final

from ._websocket import CloseCode, Opcode, close_payload, frame

__all__ = ["HIGH_WATER", "TEXT_QUEUE", "Viewer"]

HIGH_WATER: Final = 256 * 1024
"""Bytes a viewer's connection may buffer before frames are held back."""
TEXT_QUEUE: Final = 256
"""Text messages held for a viewer that cannot take them now; older ones are dropped."""


@final
class Viewer:
    """One open WebSocket: what the server sends to one page (or any client)."""

    def __init__(self, transport: asyncio.Transport) -> None:
        self._transport = transport
        self._paused = False
        self._latest: bytes | None = None  # a frame held back while paused
        self._texts: deque[bytes] = deque()
        self.skipped_frames = 0
        """Frames replaced by a later one before they could be sent."""
        self.dropped_texts = 0
        """Text messages dropped from a full queue."""
        self.sent_frames = 0
        self.closed = False

    def send_frame(self, data: bytes) -> None:
        """Sends a binary frame now, or holds it back in place of the one held (see module docs)."""
        self.send_framed(frame(Opcode.BINARY, data))

    def send_framed(self, framed: bytes) -> None:
        """:meth:`send_frame` of a message framed already (one framing for every viewer)."""
        if self.closed:
            return
        if self._paused:
            if self._latest is not None:
                self.skipped_frames += 1
            self._latest = framed
            return
        self._transport.write(framed)
        self.sent_frames += 1

    def send_text(self, text: str) -> None:
        """Sends a text message now, or queues it (bounded) behind the others."""
        if self.closed:
            return
        data = frame(Opcode.TEXT, text.encode("utf-8"))
        if not self._paused and not self._texts:
            self._transport.write(data)
            return
        if len(self._texts) >= TEXT_QUEUE:
            self._texts.popleft()
            self.dropped_texts += 1
        self._texts.append(data)

    def close(self, code: CloseCode = CloseCode.GOING_AWAY, reason: str = "") -> None:
        """Sends what waits and a close frame, then closes; a stalled viewer is cut at once."""
        if self.closed:
            return
        if self._paused:
            self.closed = True
            self._transport.abort()  # it reads nothing: what is buffered would never go
            return
        self._flush()
        self.closed = True
        self._transport.write(frame(Opcode.CLOSE, close_payload(code, reason)))
        self._transport.close()  # after the buffer is written: FIN, not a reset

    def fail(self, code: CloseCode, reason: str) -> None:
        """The client broke the protocol: a close frame, then the end of what we send.

        The connection is half-closed: what the client still sends is read and
        dropped until it closes its side, so that the close frame reaches it (closing
        with unread data would reset the connection, and could lose it).
        """
        self.closed = True
        self._transport.write(frame(Opcode.CLOSE, close_payload(code, reason)))
        if self._transport.can_write_eof():
            self._transport.write_eof()
        else:
            self._transport.close()

    @property
    def paused(self) -> bool:
        """Whether the connection's buffer is past its high-water mark (frames held back)."""
        return self._paused

    def pause(self) -> None:
        """The transport's buffer is full: hold frames back."""
        self._paused = True

    def resume(self) -> None:
        """The buffer drained: send what was held (texts first, then the latest frame)."""
        self._paused = False
        self._flush()

    def _flush(self) -> None:
        while self._texts and not self._paused:
            self._transport.write(self._texts.popleft())
        if self._latest is not None and not self._paused:
            latest, self._latest = self._latest, None
            self._transport.write(latest)
            self.sent_frames += 1

    def control(self, opcode: Opcode, payload: bytes) -> None:
        """Writes a control frame (a pong, a close): tiny, so even past the high-water mark."""
        if not self.closed:
            self._transport.write(frame(opcode, payload))
