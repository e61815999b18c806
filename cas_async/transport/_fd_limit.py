"""Making room for more file descriptors: raising the soft ``RLIMIT_NOFILE``.

Every UDP robot holds one socket, and many systems start processes with a soft
limit of 1,024 descriptors: a swarm of 1,000 robots in one process would then
fail to bind, somewhere in the middle, with "Too many open files". The soft limit
may be raised by any process up to its hard limit; :func:`ensure_descriptors`
does so on demand and, when even the hard limit is too low, says so before the
first socket fails, with what to do about it.
"""

from __future__ import annotations

import errno
import os
import sys
import threading
from typing import Final

from .._errors import ConfigurationError

if sys.platform == "win32":  # pragma: no cover - no rlimits there (nor this limit)
    _resource = None
else:
    import resource as _resource

__all__ = ["descriptor_room", "ensure_descriptors"]

_UNLIMITED: Final = sys.maxsize
"""Returned when the process has no descriptor limit this module can see."""

_ASSUMED_OPEN: Final = 64
"""Descriptors assumed open where they cannot be counted (stdio, the loop, a few files)."""

_FD_LISTINGS: Final = ("/proc/self/fd", "/dev/fd")

# Serialises read-check-raise: two threads raising at once must not lower each other.
_lock = threading.Lock()


def ensure_descriptors(needed: int) -> int:
    """Makes sure ``needed`` more descriptors than are open now can be opened.

    Raises the soft ``RLIMIT_NOFILE``, up to the hard limit, once the descriptors
    open plus ``needed`` pass half of it: to twice that sum, and at least to twice
    its old value, so that calling this before every socket stays cheap (about
    15 µs on Linux, where the size of the descriptor table spares counting them)
    and calling it again with the same number changes nothing. Never lowers the
    limit; safe to call from several threads. Without the ``resource`` module
    (Windows) it does nothing.

    Args:
        needed: descriptors about to be opened (``>= 0``).

    Returns:
        The soft limit now in effect; ``sys.maxsize`` when unlimited or unknown.

    Raises:
        ConfigurationError: the hard limit leaves no room for ``needed`` more;
            the message gives the numbers and how to raise the hard limit.
        ValueError: ``needed`` is negative.
    """
    if needed < 0:
        raise ValueError(f"needed must be >= 0, got {needed!r}")
    if _resource is None:
        return _UNLIMITED
    infinity = _resource.RLIM_INFINITY
    with _lock:
        soft, hard = _resource.getrlimit(_resource.RLIMIT_NOFILE)
        if soft == infinity:
            return _UNLIMITED
        # The descriptor table's size bounds the descriptors open: checking it first
        # avoids listing thousands of descriptors on every call.
        if _table_size() + needed <= soft:
            return soft
        target = _open_descriptors(soft) + needed
        if hard != infinity and target > hard:
            raise ConfigurationError(_too_low(needed, target - needed, soft, hard))
        # Room enough, but past half the limit: raise now (when allowed), so the
        # table-size check above answers the next calls without counting again.
        if target <= soft and (2 * target <= soft or soft == hard):
            return soft
        return _raise_soft(target, soft, hard)


def descriptor_room() -> tuple[int, int]:
    """``(room, hard)``: descriptors this process can still open, and its hard limit.

    Room is the hard limit (to which :func:`ensure_descriptors` raises the soft
    one) less the descriptors open now; both are ``sys.maxsize`` when unlimited
    or unknown.
    """
    if _resource is None:
        return _UNLIMITED, _UNLIMITED
    soft, hard = _resource.getrlimit(_resource.RLIMIT_NOFILE)
    if hard == _resource.RLIM_INFINITY:
        return _UNLIMITED, _UNLIMITED
    return max(0, hard - _open_descriptors(soft)), hard


def _raise_soft(target: int, soft: int, hard: int) -> int:
    """Raises the soft limit to twice ``target`` or ``soft`` (at most ``hard``), or to ``target``.

    Returns the soft limit in effect afterwards, never lower than ``soft``.
    """
    assert _resource is not None
    generous = max(2 * target, 2 * soft)
    if hard != _resource.RLIM_INFINITY:
        generous = min(generous, hard)
    # An infinite hard limit is still capped by the kernel (fs.nr_open): if the
    # generous value is refused, the one needed may not be.
    error: Exception | None = None
    for value in dict.fromkeys((generous, target)):
        if value <= soft:
            continue
        try:
            _resource.setrlimit(_resource.RLIMIT_NOFILE, (value, hard))
        except (OSError, ValueError) as exc:
            error = exc
        else:
            return value
    if target <= soft:  # only the head start was refused: there is room
        return soft
    raise ConfigurationError(
        f"cannot raise the soft file descriptor limit (RLIMIT_NOFILE) from {soft} to "
        f"{target}: {error}; raise it before starting (ulimit -n {target})"
    ) from error


def _too_low(needed: int, open_now: int, soft: int, hard: int) -> str:
    target = open_now + needed
    return (
        f"{needed} more file descriptors are needed ({open_now} open, {target} in all), "
        f"but the hard limit (RLIMIT_NOFILE) is {hard} (soft {soft}): only "
        f"{max(0, hard - open_now)} more fit. Raise the hard limit: `ulimit -Hn {target}` "
        "in the shell that starts the process (as root), or a `nofile` line in "
        "/etc/security/limits.conf (e.g. `*  hard  nofile  65536`), or LimitNOFILE= in "
        "a systemd unit; or run fewer robots per process"
    )


def _table_size() -> int:
    """An upper bound of the descriptors open: the size of the kernel's descriptor table.

    Linux reports it as ``FDSize`` in ``/proc/self/status``; it only grows (in
    powers of two) and is larger than every open descriptor's number. Elsewhere
    (or when it cannot be read) ``sys.maxsize``, so that the caller counts.
    """
    try:
        with open("/proc/self/status", encoding="ascii", errors="replace") as status:
            for line in status:
                if line.startswith("FDSize:"):
                    return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return _UNLIMITED


def _open_descriptors(soft: int) -> int:
    """How many descriptors are open now (the listing's own one included: one too many).

    Where no listing is available, :data:`_ASSUMED_OPEN`. When the listing cannot
    even be opened because no descriptor is left, every one is in use: ``soft``.
    """
    for listing in _FD_LISTINGS:
        try:
            return len(os.listdir(listing))
        except FileNotFoundError:
            continue
        except OSError as exc:
            if exc.errno == errno.EMFILE:
                return soft
            continue
    return _ASSUMED_OPEN
