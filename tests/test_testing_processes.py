"""peer_process: a peer in another process, ready on cue, always ended."""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path

import pytest

from cas_async.testing import peer_process

PYTHON = sys.executable


async def test_the_peer_is_ready_then_ended() -> None:
    script = "import time; print('ready', flush=True); print('more', flush=True); time.sleep(60)"
    async with peer_process(PYTHON, "-c", script) as process:
        assert process.stdout is not None
        assert (await process.stdout.readline()).strip() == b"more"
        assert process.returncode is None
    assert process.returncode is not None  # killed on the way out, not left behind


def alive(token: str) -> list[str]:
    """The processes whose command line holds ``token``."""
    found = []
    for entry in Path("/proc").iterdir():
        with contextlib.suppress(OSError):
            if entry.name.isdigit() and token in (entry / "cmdline").read_text():
                found.append(entry.name)
    return found


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads /proc")
async def test_a_peer_that_is_never_ready_times_out_and_is_ended() -> None:
    token = f"never-ready-{os.getpid()}"
    with pytest.raises(TimeoutError, match=r"did not print 'ready' within 0\.5 s"):
        async with peer_process(
            PYTHON, "-c", f"import time; time.sleep(60)  # {token}", timeout=0.5
        ):
            raise AssertionError("not reached")
    assert alive(token) == []


async def test_a_chatty_peer_does_not_block_on_its_stderr() -> None:
    script = "import sys; sys.stderr.write('x' * 1_000_000); sys.stderr.flush(); print('ready')"
    async with peer_process(PYTHON, "-c", script, timeout=10.0) as process:
        assert process.returncode is None or process.returncode == 0


async def test_a_peer_that_dies_first_says_why() -> None:
    script = "import sys; sys.stderr.write('no luck'); sys.exit(3)"
    with pytest.raises(RuntimeError, match=r"ended \(exit 3\) before printing 'ready': no luck"):
        async with peer_process(PYTHON, "-c", script):
            pass


@pytest.mark.cas_virtual
async def test_virtual_time_cannot_wait_for_another_process() -> None:
    with pytest.raises(RuntimeError, match="real-time loop"):
        async with peer_process(PYTHON, "-c", "print('ready')"):
            pass
