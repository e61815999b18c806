"""Choosing the event loop: uvloop by default when installed, opt-out, or virtual time."""

from __future__ import annotations

import asyncio

import pytest

import cas_async
from cas_async import Robot, UdpTransport, VirtualTimeLoop
from tests.stacks import STACK_MESSAGES, Note, recorders


async def _loop_type() -> type:
    return type(asyncio.get_running_loop())


def test_uvloop_is_used_when_installed(monkeypatch: pytest.MonkeyPatch) -> None:
    if not cas_async.uvloop_available():
        pytest.skip("uvloop is not installed")
    monkeypatch.delenv("CAS_ASYNC_UVLOOP", raising=False)
    assert cas_async.run(_loop_type()).__module__.startswith("uvloop")


@pytest.mark.parametrize("value", ["0", "false", "off", "NO"])
def test_uvloop_opt_out_by_environment(monkeypatch: pytest.MonkeyPatch, value: str) -> None:
    monkeypatch.setenv("CAS_ASYNC_UVLOOP", value)
    assert cas_async.run(_loop_type()).__module__.startswith("asyncio")


def test_uvloop_opt_out_by_argument() -> None:
    assert cas_async.run(_loop_type(), use_uvloop=False).__module__.startswith("asyncio")


def test_virtual_time_uses_the_virtual_loop() -> None:
    assert cas_async.run(_loop_type(), virtual=True) is VirtualTimeLoop


@pytest.mark.parametrize("use_uvloop", [False, True], ids=["stdlib", "uvloop"])
def test_socket_errors_are_counted_not_raised(use_uvloop: bool) -> None:
    if use_uvloop and not cas_async.uvloop_available():
        pytest.skip("uvloop is not installed")

    async def main() -> dict[str, int]:
        transport = UdpTransport()
        transport.directory.add(9, "127.0.0.1", 0)  # the kernel refuses to send to port 0
        stack = recorders(1)
        async with Robot(1, stack, transport=transport, messages=STACK_MESSAGES) as robot:
            stack[0].send(9, Note("nowhere", []))
            for _ in range(20):
                await asyncio.sleep(0)
            return robot.dropped

    assert cas_async.run(main(), use_uvloop=use_uvloop) == {"transport.socket_error": 1}
