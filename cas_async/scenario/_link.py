"""The control channel of a simulation spread over processes: small signed messages on Zenoh.

Messages are msgpack lists ``[kind, ...]`` published under ``{namespace}/ctl/...``.
With a swarm key each carries an HMAC-SHA256 tag (16 bytes) over its key expression
and payload: a process without the key can neither forge nor alter one, nor replay
one under another key. (Within one key, a replay is possible for whoever can
publish on the router; every run has its own random namespace, so nothing recorded
from another run applies.) Messages that fail the check, or do not parse, are
dropped and counted in :attr:`Link.dropped`.

Like the Zenoh transport, a link has one subscriber per key it listens to, and
hands what arrives to the event loop in batches (the transport's :class:`ThreadInbox`).
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import hmac
from collections.abc import Callable
from typing import Any, Final

import msgpack

from .._swarm_key import SwarmKey
from ..transport._zenoh import ThreadInbox

__all__ = ["Link"]

_TAG: Final = 16


class Link:
    """Publishes and receives control messages through a Zenoh session.

    Args:
        session: an open ``zenoh.Session`` (the caller closes it).
        namespace: the run's key prefix.
        key: the swarm key that signs every message, or ``None``.
        handle: called on the event loop with ``(suffix, message)`` for each valid
            message (``suffix`` is the key after ``{namespace}/ctl/``).
    """

    def __init__(
        self,
        session: Any,
        namespace: str,
        key: SwarmKey | None,
        handle: Callable[[str, list[Any]], None],
    ) -> None:
        import zenoh

        self._zenoh = zenoh
        self._session = session
        self._prefix = f"{namespace}/ctl/"
        self._secret = None if key is None else key.secret
        self._handle = handle
        self._inbox: ThreadInbox[tuple[str, bytes]] = ThreadInbox(
            asyncio.get_running_loop(), self._drain
        )
        self._subscribers: list[Any] = []
        self._block = zenoh.CongestionControl.BLOCK
        self.dropped = 0
        """Messages refused: unsigned, forged, or not a message."""

    def listen(self, suffix: str) -> None:
        """Receives what is published under ``{namespace}/ctl/{suffix}`` (wildcards allowed)."""
        self._subscribers.append(
            self._session.declare_subscriber(
                self._prefix + suffix,
                lambda sample: self._inbox.put((str(sample.key_expr), sample.payload.to_bytes())),
            )
        )

    def send(self, suffix: str, message: list[Any]) -> None:
        """Publishes ``message`` under ``{namespace}/ctl/{suffix}``, reliably."""
        key = self._prefix + suffix
        payload = msgpack.packb(message, use_bin_type=True)
        if self._secret is not None:
            payload += _tag(self._secret, key, payload)
        self._session.put(key, payload, congestion_control=self._block)

    def close(self) -> None:
        """Stops receiving (the session stays open); idempotent."""
        subscribers, self._subscribers = self._subscribers, []
        for subscriber in subscribers:
            with contextlib.suppress(Exception):
                subscriber.undeclare()

    def _drain(self, entries: list[tuple[str, bytes]]) -> None:
        for key, payload in entries:
            if self._secret is not None:
                body, tag = payload[:-_TAG], payload[-_TAG:]
                if len(payload) < _TAG or not hmac.compare_digest(
                    tag, _tag(self._secret, key, body)
                ):
                    self.dropped += 1
                    continue
                payload = body
            try:
                message = msgpack.unpackb(payload, raw=False, strict_map_key=False)
            except Exception:
                self.dropped += 1
                continue
            if not isinstance(message, list) or not message or not isinstance(message[0], str):
                self.dropped += 1
                continue
            self._handle(key[len(self._prefix) :], message)


def _tag(secret: bytes, key: str, payload: bytes) -> bytes:
    """The signature of ``payload`` published under ``key``."""
    return hmac.new(secret, key.encode() + b"\0" + payload, hashlib.sha256).digest()[:_TAG]
