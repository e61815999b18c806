"""Zenoh sessions that stay on this machine unless told otherwise; a clear error without zenoh."""

from __future__ import annotations

import ipaddress
import json
import socket
import warnings
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Final, Literal

from ..._errors import ConfigurationError
from .._udp import InsecureBindWarning

if TYPE_CHECKING:
    import zenoh

__all__ = [
    "LOOPBACK_LISTEN",
    "Mode",
    "beyond_loopback",
    "import_zenoh",
    "loopback_config",
    "warn_if_exposed",
    "with_free_port",
]

Mode = Literal["peer", "client", "router"]

LOOPBACK_LISTEN: Final = ("tcp/127.0.0.1:0",)
"""Where a session listens by default: loopback, a port the OS picks."""


def import_zenoh() -> Any:
    """The ``zenoh`` module, or a ``ConfigurationError`` saying how to install it."""
    try:
        import zenoh
    except ImportError as exc:
        raise ConfigurationError(
            'the Zenoh transport needs eclipse-zenoh: pip install "cas_async[zenoh]"'
        ) from exc
    return zenoh


def loopback_config(
    *, mode: Mode = "peer", listen: Sequence[str] = LOOPBACK_LISTEN, connect: Sequence[str] = ()
) -> zenoh.Config:
    """A Zenoh configuration that stays on this machine unless ``listen``/``connect`` say so.

    Multicast scouting is off (it would announce the session on the LAN) and the
    session listens on the endpoints given, loopback by default.

    Raises:
        ConfigurationError: zenoh is not installed, or an endpoint is not valid.
    """
    config: zenoh.Config = import_zenoh().Config()
    try:
        config.insert_json5("mode", json.dumps(mode))
        config.insert_json5("listen/endpoints", json.dumps(list(listen)))
        config.insert_json5("connect/endpoints", json.dumps(list(connect)))
        config.insert_json5("scouting/multicast/enabled", "false")
    except Exception as exc:  # zenoh.ZError: the message names the bad value
        raise ConfigurationError(f"Zenoh configuration: {exc}") from exc
    return config


def beyond_loopback(endpoint: str) -> bool:
    """Whether a Zenoh endpoint (``tcp/HOST:PORT``) listens beyond this machine."""
    _, _, address = endpoint.partition("/")
    host = address.rsplit(":", 1)[0].strip("[]")
    try:
        return not ipaddress.ip_address(host).is_loopback
    except ValueError:  # a name, or an interface: assume the worst
        return host != "localhost"


def warn_if_exposed(listen: Sequence[str]) -> None:
    """Warns (``InsecureBindWarning``) if a session without a swarm key listens beyond loopback."""
    exposed = [endpoint for endpoint in listen if beyond_loopback(endpoint)]
    if exposed:
        warnings.warn(
            f"Zenoh session listens on {', '.join(exposed)} without authentication: "
            "anyone who can reach it can send robots messages. Give the swarm a key "
            "(CAS_ASYNC_SWARM_KEY=<hex> or a key file, see SwarmKey) and wrap the "
            "transport in AuthenticatedTransport, or listen on tcp/127.0.0.1",
            InsecureBindWarning,
            stacklevel=4,
        )


def with_free_port(endpoint: str) -> str:
    """``endpoint`` with port 0 replaced by one free now (Zenoh does not say which it bound)."""
    head, _, port = endpoint.rpartition(":")
    if port != "0":
        return endpoint
    _, _, host = head.partition("/")
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as probe:
        probe.bind((host.strip("[]"), 0))
        return f"{head}:{probe.getsockname()[1]}"
