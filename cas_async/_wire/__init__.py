"""The wire (internal): what crosses between robots, and how it is sealed.

Messages and their stable tags (``_message``), the msgpack codec with its limits
(``_codec``), what a transport carries: bytes or the objects themselves
(``_payloads``), stack fingerprints (``_fingerprint``, DESIGN rule 5), the swarm key
(``_swarm_key``) and the signed proofs of presence (``_presence``).

Imports only the ground (``cas_async._errors``, ``cas_async._types``). Public names
are re-exported by ``cas_async`` and ``cas_async.transport``.
"""

__all__: list[str] = []
