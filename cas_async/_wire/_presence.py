"""Proofs of presence: a robot's claim to live somewhere, signed with the swarm key.

A transport that learns from the network where robots live (``ZenohTransport``'s
liveliness tokens) believes anyone who declares one, unless the claims carry a proof.
:class:`~cas_async.transport._authenticated.AuthenticatedTransport` hands its inner
transport a :class:`PresenceSeal`
(:meth:`~cas_async._core._transport_contract.Transport.require_proof`);
the transport then signs the claims of its own robots and believes only the claims
that verify.

The seal's key is derived from the swarm key (HMAC-SHA256 of the swarm key over a
fixed label), so a proof of presence is never a valid datagram tag, nor the reverse.
A claim is text that names everything it binds (for Zenoh: the namespace, the robot,
the session and a :func:`stamp`); its proof is HMAC-SHA256 over it, truncated to 16
bytes, as 32 hex digits. A proof can be copied, as anything sent in clear: it binds
the claim to one session and one stamp, so a copy says nothing new (see the
transport for what it does with one).
"""

from __future__ import annotations

import hmac
import time
from typing import Final, final

from ._swarm_key import SwarmKey

__all__ = ["PROOF_DIGITS", "PresenceSeal", "stamp"]

_LABEL: Final = b"cas_async presence v1"
_PROOF_BYTES: Final = 16
PROOF_DIGITS: Final = 2 * _PROOF_BYTES
"""Hex digits of a proof."""


def stamp(after: int = 0) -> int:
    """Microseconds since the epoch, and above ``after``: when a robot claims a place.

    Not a time measurement (STYLE rule 9 is about those): a number that grows across
    the restarts of a process, as the first counter of an authenticated endpoint
    does, so the wall clock, even in virtual time.
    """
    return max(time.time_ns() // 1000, after + 1)


@final
class PresenceSeal:
    """Signs claims of presence, and checks them, with a key derived from the swarm key.

    Args:
        key: the key every robot of the swarm holds.
    """

    __slots__ = ("_mac",)

    def __init__(self, key: SwarmKey) -> None:
        derived = hmac.new(key.secret, _LABEL, "sha256").digest()
        self._mac = hmac.new(derived, digestmod="sha256")

    def sign(self, claim: str) -> str:
        """The proof of ``claim``: 32 lowercase hex digits."""
        mac = self._mac.copy()
        mac.update(claim.encode())
        return mac.hexdigest()[:PROOF_DIGITS]

    def verifies(self, claim: str, proof: str) -> bool:
        """Whether ``proof`` is the proof of ``claim`` (in constant time)."""
        return hmac.compare_digest(self.sign(claim), proof)

    def __repr__(self) -> str:
        return "PresenceSeal(<key hidden>)"
