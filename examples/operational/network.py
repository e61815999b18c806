"""Where the rendezvous swarm meets on Zenoh: its namespace and its default endpoint.

The endpoint is on loopback, so by default nothing leaves this machine. To meet
robots on other hosts, the swarm process listens on an address they can reach (and
the swarm should then have a key: see ``ZenohTransport``).
"""

from __future__ import annotations

from typing import Final

__all__ = ["ENDPOINT", "NAMESPACE"]

NAMESPACE: Final = "rendezvous"
"""The Zenoh key prefix of the swarm: only robots under it see each other."""

ENDPOINT: Final = "tcp/127.0.0.1:7447"
"""Where the swarm process listens and operational robots connect (Zenoh's usual port)."""
