"""What SIGINT and SIGTERM do while the command line runs, in this process (main thread)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator

import pytest

from cas_async._cli._interrupts import Interrupted, Interrupts

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")


def _raise(signum: int) -> None:
    os.kill(os.getpid(), signum)


@pytest.fixture
def interrupts() -> Iterator[Interrupts]:
    taken = Interrupts().install()
    yield taken
    taken.restore()


def test_by_default_a_signal_raises_interrupted(interrupts: Interrupts) -> None:
    with pytest.raises(Interrupted) as caught:
        _raise(signal.SIGTERM)
    assert caught.value.signum == signal.SIGTERM
    assert str(caught.value) == "interrupted by SIGTERM"
    assert not isinstance(caught.value, Exception)  # `except Exception` cannot swallow it
    assert interrupts.received == [signal.SIGTERM]


def test_calling_runs_the_action_instead(interrupts: Interrupts) -> None:
    called: list[str] = []
    with interrupts.calling(lambda: called.append("stop")):
        _raise(signal.SIGINT)
        _raise(signal.SIGTERM)
    assert called == ["stop", "stop"]
    assert interrupts.received == [signal.SIGINT, signal.SIGTERM]
    with pytest.raises(Interrupted):  # the action is gone with the block
        _raise(signal.SIGINT)


def test_deferred_only_notes_even_inside_calling(interrupts: Interrupts) -> None:
    called: list[str] = []
    with interrupts.calling(lambda: called.append("stop")), interrupts.deferred():
        _raise(signal.SIGINT)
    assert called == []
    assert interrupts.interrupted


def test_restore_gives_the_handlers_back() -> None:
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    taken = Interrupts().install()
    assert signal.getsignal(signal.SIGINT) != before[0]
    taken.restore()
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before


def test_outside_the_main_thread_nothing_is_installed() -> None:
    before = signal.getsignal(signal.SIGINT)
    seen: list[object] = []

    def install() -> None:
        Interrupts().install()
        seen.append(signal.getsignal(signal.SIGINT))

    thread = threading.Thread(target=install)
    thread.start()
    thread.join(10)
    assert seen == [before]


def test_importing_the_library_leaves_the_signal_handlers_alone() -> None:
    # Only `python -m cas_async` takes over the signals (in cas_async.__main__): a
    # program or a test that imports the library keeps its own handlers.
    script = (
        "import signal\n"
        "before = [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)]\n"
        "import cas_async, cas_async.scenario, cas_async.sim, cas_async.transport\n"
        "cas_async.Robot, cas_async.Layer\n"
        "after = [signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)]\n"
        "print(before == after)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=True
    )
    assert done.stdout.strip() == "True", done.stderr
