"""Choosing the event loop: uvloop by default when installed, opt-out, or virtual time."""

from __future__ import annotations

import asyncio

import pytest

import cas_async
from cas_async import Robot, UdpTransport, VirtualTimeLoop
from tests.stacks import STACK_MESSAGES, recorders


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


async def test_socket_errors_are_counted_not_raised() -> None:
    async with Robot(1, recorders(1), transport=UdpTransport(), messages=STACK_MESSAGES) as robot:
        endpoint = robot._endpoint
        assert endpoint is not None
        # What the loop calls when the kernel reports e.g. ICMP port unreachable.
        endpoint._transport.get_protocol().error_received(ConnectionRefusedError(111, "refused"))  # type: ignore[attr-defined]
        assert robot.dropped == {"transport.socket_error": 1}
