"""The secret a swarm shares to authenticate its datagrams, and where it comes from.

A key is at least 16 random bytes (32 recommended: :meth:`SwarmKey.generate`). It
reaches a robot from the environment (:meth:`SwarmKey.from_env`, hex in
``CAS_ASYNC_SWARM_KEY``) or from a file only its user can read
(:meth:`SwarmKey.from_file`), never from a scenario file: scenarios are shared,
committed and printed, a secret must not be. Make one with::

    python -c "from cas_async import SwarmKey; print(SwarmKey.generate().hex())" > swarm.key
    chmod 600 swarm.key

Nothing here ever shows the secret: not the repr, not an error message. Two keys
can be told apart by :attr:`SwarmKey.fingerprint`, a hash that reveals nothing of
the secret, which is how to check that two robots were given the same key.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import secrets
import stat
import warnings
from dataclasses import dataclass, field
from typing import ClassVar, Final, final

from .._errors import ConfigurationError

__all__ = ["KeyFileWarning", "SwarmKey"]

_ENV_VAR: Final = "CAS_ASYNC_SWARM_KEY"
_MIN_BYTES: Final = 16  # 128 bits, below which guessing becomes thinkable
_GENERATED_BYTES: Final = 32


class KeyFileWarning(UserWarning):
    """A key file others than its owner can read or write: the secret may have leaked."""


@final
@dataclass(frozen=True, eq=False, repr=False)
class SwarmKey:
    """A shared secret for :class:`~cas_async.transport._authenticated.AuthenticatedTransport`.

    Args:
        secret: the key, at least :attr:`MIN_BYTES` bytes.

    Raises:
        ConfigurationError: ``secret`` is not bytes or is too short.
    """

    ENV_VAR: ClassVar[str] = _ENV_VAR
    """The environment variable :meth:`from_env` reads by default (hex)."""
    MIN_BYTES: ClassVar[int] = _MIN_BYTES
    """Shortest secret accepted."""

    secret: bytes = field(repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.secret, bytes):
            raise ConfigurationError(
                f"a swarm key is bytes, got {type(self.secret).__name__}; "
                "use SwarmKey.from_env() or SwarmKey.from_file() to read a hex key"
            )
        if len(self.secret) < _MIN_BYTES:
            raise ConfigurationError(
                f"a swarm key needs at least {_MIN_BYTES} bytes, got {len(self.secret)}; "
                "make one with SwarmKey.generate()"
            )

    @classmethod
    def generate(cls) -> SwarmKey:
        """A new random key of 32 bytes (write it out with :meth:`hex`)."""
        return cls(secrets.token_bytes(_GENERATED_BYTES))

    @classmethod
    def from_env(cls, var: str = _ENV_VAR) -> SwarmKey | None:
        """The key held as hex in environment variable ``var``; ``None`` when unset or empty.

        Raises:
            ConfigurationError: the value is not hex, or has fewer than 32 hex digits
                (16 bytes). The message names the variable, never its value.
        """
        value = os.environ.get(var, "").strip()
        if not value:
            return None
        secret = _from_hex(value)
        if secret is None:
            raise ConfigurationError(
                f"environment variable {var} must hold the swarm key as hex digits "
                f"(at least {2 * _MIN_BYTES}), but its value is not hex; "
                "make a key with SwarmKey.generate().hex()"
            )
        if len(secret) < _MIN_BYTES:
            raise ConfigurationError(
                f"environment variable {var} holds {2 * len(secret)} hex digits; a swarm key "
                f"needs at least {2 * _MIN_BYTES}"
            )
        return cls(secret)

    @classmethod
    def from_file(cls, path: str | os.PathLike[str]) -> SwarmKey:
        """The key in file ``path``: hex text (surrounding whitespace ignored), else raw bytes.

        A file that is not hex is taken byte for byte (e.g. ``head -c 32 /dev/urandom``),
        so a trailing newline would be part of the key. On POSIX a file that group or
        others may read or write raises a :class:`KeyFileWarning`.

        Raises:
            ConfigurationError: the file cannot be read, its hex is shorter than 16
                bytes, or (not hex) it holds fewer than 16 bytes. The message names the
                file, never its content.
        """
        name = os.fspath(path)
        try:
            with open(name, "rb") as file:
                # fstat on the open file: the mode checked is the mode of what is read.
                mode = os.fstat(file.fileno()).st_mode
                data = file.read()
        except OSError as exc:
            raise ConfigurationError(
                f"cannot read the swarm key file {name!r}: {exc.strerror or exc}"
            ) from None
        if os.name == "posix" and mode & (stat.S_IRWXG | stat.S_IRWXO):
            warnings.warn(
                f"swarm key file {name!r} is accessible to group or others "
                f"(mode {stat.filemode(mode)}); anyone who reads it can forge datagrams "
                f"for the swarm: chmod 600 {name!r}",
                KeyFileWarning,
                stacklevel=2,
            )
        secret = _from_hex(_ascii(data).strip())
        if secret is not None:
            if len(secret) < _MIN_BYTES:
                raise ConfigurationError(
                    f"swarm key file {name!r} holds {2 * len(secret)} hex digits; a swarm key "
                    f"needs at least {2 * _MIN_BYTES}"
                )
            return cls(secret)
        if len(data) < _MIN_BYTES:
            raise ConfigurationError(
                f"swarm key file {name!r} holds {len(data)} bytes; a swarm key needs at least "
                f"{_MIN_BYTES} (as raw bytes) or {2 * _MIN_BYTES} hex digits"
            )
        return cls(data)

    def hex(self) -> str:
        """The secret as hex digits, the form :meth:`from_env` and :meth:`from_file` read."""
        return self.secret.hex()

    @property
    def fingerprint(self) -> str:
        """8 hex digits that tell keys apart without revealing them."""
        # Domain-separated, so the fingerprint is no MAC of anything sent on the wire.
        return hashlib.sha256(b"cas_async swarm key fingerprint\0" + self.secret).hexdigest()[:8]

    def __repr__(self) -> str:
        return f"SwarmKey(<{len(self.secret)} bytes, fingerprint {self.fingerprint}>)"

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, SwarmKey):
            return NotImplemented
        return hmac.compare_digest(self.secret, other.secret)

    def __hash__(self) -> int:
        return hash(self.fingerprint)


def _ascii(data: bytes) -> str:
    """``data`` as text if it is ASCII, else an empty string (not hex)."""
    try:
        return data.decode("ascii")
    except UnicodeDecodeError:
        return ""


def _from_hex(text: str) -> bytes | None:
    """The bytes ``text`` spells in hex, ``None`` if it is empty or not hex."""
    if not text:
        return None
    try:
        return bytes.fromhex(text)
    except ValueError:
        return None
