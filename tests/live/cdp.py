"""A headless Chromium driven over its DevTools protocol (a WebSocket of JSON commands).

Just what the browser tests need: open a page, evaluate JavaScript, take a
screenshot. Debian's ``chromium`` is used (Playwright's own browser download does
not work here); the client is the ``websockets`` package, in the dev extra.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import itertools
import json
import shutil
import subprocess
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
    "--force-device-scale-factor=1",
    "--window-size=1200,760",
)
START_LIMIT = 30.0


def chromium() -> str | None:
    """The browser's path, or ``None``."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


class Page:
    """One tab, attached with a flat session."""

    def __init__(self, browser: Browser, session: str) -> None:
        self._browser = browser
        self._session = session

    async def evaluate(self, expression: str) -> Any:
        """The value of ``expression`` (awaited when it is a promise)."""
        reply = await self._browser.call(
            "Runtime.evaluate",
            {"expression": expression, "returnByValue": True, "awaitPromise": True},
            self._session,
        )
        if "exceptionDetails" in reply:
            raise RuntimeError(f"JavaScript failed: {reply['exceptionDetails']}")
        return reply["result"].get("value")

    async def wait_for(self, expression: str, limit: float = 30.0) -> Any:
        """Evaluates ``expression`` until it is truthy; returns its value."""
        deadline = time.monotonic() + limit
        while True:
            value = await self.evaluate(expression)
            if value:
                return value
            if time.monotonic() > deadline:
                raise TimeoutError(f"still false after {limit} s: {expression}")
            await asyncio.sleep(0.05)

    async def screenshot(self, path: Path) -> Path:
        """A PNG of the viewport, written to ``path``."""
        reply = await self._browser.call("Page.captureScreenshot", {"format": "png"}, self._session)
        path.write_bytes(base64.b64decode(reply["data"]))  # noqa: ASYNC240 - small
        return path


class Browser:
    """A DevTools connection: commands by id, their replies matched as they come."""

    def __init__(self, socket: Any) -> None:
        self._socket = socket
        self._ids = itertools.count(1)
        self._waiting: dict[int, asyncio.Future[dict[str, Any]]] = {}
        self._reader = asyncio.ensure_future(self._read())

    async def _read(self) -> None:
        async for raw in self._socket:
            message = json.loads(raw)
            future = self._waiting.pop(message.get("id", -1), None)
            if future is not None and not future.done():
                future.set_result(message)

    async def call(self, method: str, params: dict[str, Any], session: str | None = None) -> Any:
        ident = next(self._ids)
        future: asyncio.Future[dict[str, Any]] = asyncio.get_running_loop().create_future()
        self._waiting[ident] = future
        command: dict[str, Any] = {"id": ident, "method": method, "params": params}
        if session is not None:
            command["sessionId"] = session
        await self._socket.send(json.dumps(command))
        reply = await asyncio.wait_for(future, 30)
        if "error" in reply:
            raise RuntimeError(f"{method}: {reply['error']}")
        return reply["result"]

    async def open(self, url: str) -> Page:
        """A new tab at ``url``, once loaded."""
        target = await self.call("Target.createTarget", {"url": "about:blank"})
        attached = await self.call(
            "Target.attachToTarget", {"targetId": target["targetId"], "flatten": True}
        )
        page = Page(self, attached["sessionId"])
        await self.call("Page.enable", {}, attached["sessionId"])
        await self.call("Page.navigate", {"url": url}, attached["sessionId"])
        await page.wait_for("document.readyState === 'complete'")
        return page

    def close(self) -> None:
        self._reader.cancel()


@contextlib.asynccontextmanager
async def launch(profile: Path) -> AsyncIterator[Browser]:
    """Starts headless Chromium with a fresh profile; stops it on leaving."""
    import websockets

    path = chromium()
    assert path is not None
    process = subprocess.Popen(  # noqa: ASYNC220 - it starts in the background
        [path, *FLAGS, f"--user-data-dir={profile}", "--remote-debugging-port=0", "about:blank"],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        active = profile / "DevToolsActivePort"
        deadline = time.monotonic() + START_LIMIT
        while not (active.exists() and len(active.read_text().splitlines()) >= 2):
            if process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"chromium did not start (exit {process.poll()})")
            await asyncio.sleep(0.05)
        port, path_ = active.read_text().splitlines()[:2]
        async with websockets.connect(f"ws://127.0.0.1:{port}{path_}", max_size=None) as socket:
            browser = Browser(socket)
            try:
                yield browser
            finally:
                browser.close()
    finally:
        process.terminate()
        try:
            process.wait(10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
