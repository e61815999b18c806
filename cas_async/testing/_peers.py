"""A peer in another process, for tests: started, awaited until ready, always ended."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Mapping
from contextlib import asynccontextmanager

from .. import VirtualTimeLoop

__all__ = ["peer_process"]


@asynccontextmanager
async def peer_process(
    *argv: str, ready: str = "ready", timeout: float = 10.0, env: Mapping[str, str] | None = None
) -> AsyncIterator[asyncio.subprocess.Process]:
    """Starts ``argv``, waits until it prints the line ``ready``, and always ends it after.

    For tests with robots in another process (real UDP on loopback, say). Its stdin
    and stdout are pipes (what it prints after ``ready`` is the test's to read); its
    stderr is read all along (so that it never blocks on a full pipe) and its end
    quoted if the process dies before it is ready. Leaving the block kills the
    process if it still runs and reaps it (5 s at most), whatever happened in the
    block.

    Raises:
        TimeoutError: no ``ready`` line within ``timeout`` (wall) seconds.
        RuntimeError: the process ended before it was ready (with its exit status
            and the end of its stderr), or the loop runs on virtual time (where
            waiting for another process cannot be timed).
    """
    if isinstance(asyncio.get_running_loop(), VirtualTimeLoop):
        raise RuntimeError("peer_process needs a real-time loop (not @pytest.mark.cas_virtual)")
    process = await asyncio.create_subprocess_exec(
        *argv,
        stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
        env=None if env is None else dict(env),
    )
    stdout, stderr = process.stdout, process.stderr
    if stdout is None or stderr is None:  # pragma: no cover - pipes were asked for
        raise RuntimeError("asyncio gave the process no pipes")
    said = bytearray()  # the end of its stderr
    draining = asyncio.ensure_future(_drain(stderr, said))
    try:
        try:
            async with asyncio.timeout(timeout):
                while (line := await stdout.readline()).decode().strip() != ready:
                    if not line:  # end of output: the process is gone
                        status = await process.wait()
                        await draining
                        raise RuntimeError(
                            f"{argv[0]} ended (exit {status}) before printing {ready!r}: "
                            + said.decode(errors="replace")
                        )
        except TimeoutError:
            raise TimeoutError(f"{argv[0]} did not print {ready!r} within {timeout:g} s") from None
        yield process
    finally:
        if process.returncode is None:
            with contextlib.suppress(ProcessLookupError):  # it may have just ended
                process.kill()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(5.0):
                # Reaped, and its pipes read to the end: asyncio then closes them.
                await asyncio.gather(process.wait(), stdout.read(), draining)
        draining.cancel()
        if process.stdin is not None:
            process.stdin.close()


async def _drain(stream: asyncio.StreamReader, tail: bytearray, keep: int = 500) -> None:
    """Reads ``stream`` to its end, keeping its last ``keep`` bytes in ``tail``."""
    while chunk := await stream.read(65536):
        tail += chunk
        del tail[:-keep]
