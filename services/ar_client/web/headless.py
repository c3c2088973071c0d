"""Headless Chromium driven over the Chrome DevTools Protocol, for end-to-end tests and benchmarks.

Uses the machine's Chromium (Debian's ``chromium`` package; ``$ARROCH_CHROMIUM`` to point
elsewhere) — never a browser downloaded by a test tool — with the flags that keep it off the
network (no background connections, no component updates, no sync) and a fresh profile per run.
A fake camera plays a Y4M file (:mod:`.fakecam`); the media permission prompt is answered yes.

The browser runs in its own process group and :meth:`Browser.close` ends the whole group, so no
renderer or GPU helper outlives a test. CDP goes over a WebSocket with aiohttp's client (no extra
driver); calls are made from synchronous code through a private event loop on a thread.
"""

from __future__ import annotations

import asyncio
import base64
import itertools
import json
import os
import shutil
import signal
import socket
import subprocess
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import aiohttp

CANDIDATES = ("chromium", "chromium-browser", "google-chrome")
FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-default-apps",
    "--mute-audio",
    "--hide-scrollbars",
    # A foreground page must keep its timers and frames running when nobody looks at it.
    "--disable-background-timer-throttling",
    "--disable-renderer-backgrounding",
    "--disable-backgrounding-occluded-windows",
)


class BrowserError(RuntimeError):
    pass


def chromium_path() -> str | None:
    """The Chromium executable, or None when the machine has none."""
    env = os.environ.get("ARROCH_CHROMIUM")
    if env:
        return env if Path(env).exists() else None
    for name in CANDIDATES:
        path = shutil.which(name)
        if path:
            return path
    return None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Browser:
    """One headless Chromium with one page, and a synchronous CDP client for that page."""

    def __init__(
        self,
        *,
        fake_camera: str | Path | None = None,
        window: tuple[int, int] = (1280, 800),
        ignore_certificate_errors: bool = True,
        extra_flags: tuple[str, ...] = (),
    ) -> None:
        exe = chromium_path()
        if exe is None:
            raise BrowserError("no Chromium on this machine (Debian: apt-get install chromium)")
        self.profile = tempfile.mkdtemp(prefix="arroch-chromium-")
        self.port = _free_port()
        argv = [
            exe,
            *FLAGS,
            f"--user-data-dir={self.profile}",
            f"--remote-debugging-port={self.port}",
            "--remote-debugging-address=127.0.0.1",
            f"--window-size={window[0]},{window[1]}",
        ]
        if fake_camera is not None:
            argv += [
                "--use-fake-device-for-media-stream",
                "--use-fake-ui-for-media-stream",
                f"--use-file-for-fake-video-capture={fake_camera}",
            ]
        if ignore_certificate_errors:
            # The test server's certificate comes from an authority the fresh profile cannot know.
            argv.append("--ignore-certificate-errors")
        argv += [*extra_flags, "about:blank"]
        self.log_path = Path(self.profile) / "chromium.log"
        self._log = self.log_path.open("wb")
        self.proc = subprocess.Popen(
            argv, stdin=subprocess.DEVNULL, stdout=self._log, stderr=subprocess.STDOUT, start_new_session=True
        )
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="cdp", daemon=True)
        self._thread.start()
        self._ids = itertools.count(1)
        self._pending: dict[int, asyncio.Future] = {}
        self.events: list[dict[str, Any]] = []
        self._http: aiohttp.ClientSession | None = None
        self._ws: aiohttp.ClientWebSocketResponse | None = None
        self._reader: asyncio.Future | None = None
        try:
            self._run(self._attach(), timeout=30.0)
        except Exception:
            self.close()
            raise

    # ------------------------------------------------------------------ plumbing

    def _run(self, coro, timeout: float) -> Any:  # noqa: ANN001
        return asyncio.run_coroutine_threadsafe(coro, self._loop).result(timeout)

    async def _attach(self) -> None:
        self._http = aiohttp.ClientSession()
        deadline = time.monotonic() + 25.0
        page = None
        while page is None:
            if self.proc.poll() is not None:
                raise BrowserError(f"Chromium exited ({self.proc.returncode}); see {self.log_path}")
            try:
                async with self._http.get(f"http://127.0.0.1:{self.port}/json/list") as response:
                    targets = await response.json()
                page = next((t for t in targets if t.get("type") == "page"), None)
            except (aiohttp.ClientError, json.JSONDecodeError):
                pass
            if page is None:
                if time.monotonic() > deadline:
                    raise BrowserError("Chromium's DevTools endpoint did not come up")
                await asyncio.sleep(0.2)
        self._ws = await self._http.ws_connect(page["webSocketDebuggerUrl"], max_msg_size=0)
        self._reader = asyncio.ensure_future(self._read())
        await self._call("Page.enable", {})
        await self._call("Runtime.enable", {})

    async def _read(self) -> None:
        assert self._ws is not None
        async for msg in self._ws:
            if msg.type != aiohttp.WSMsgType.TEXT:
                continue
            data = json.loads(msg.data)
            if "id" in data:
                future = self._pending.pop(data["id"], None)
                if future is not None and not future.done():
                    future.set_result(data)
            else:
                self.events.append(data)
                if len(self.events) > 10000:
                    del self.events[:5000]
        for future in self._pending.values():
            if not future.done():
                future.set_exception(BrowserError("DevTools connection closed"))

    async def _call(self, method: str, params: dict[str, Any]) -> dict[str, Any]:
        assert self._ws is not None
        call_id = next(self._ids)
        future = self._loop.create_future()
        self._pending[call_id] = future
        await self._ws.send_str(json.dumps({"id": call_id, "method": method, "params": params}))
        data = await future
        if "error" in data:
            raise BrowserError(f"{method}: {data['error']}")
        return data.get("result", {})

    # ------------------------------------------------------------------ what tests use

    def call(self, method: str, timeout: float = 30.0, **params: Any) -> dict[str, Any]:
        return self._run(self._call(method, params), timeout)

    def navigate(self, url: str, timeout: float = 30.0) -> None:
        self.call("Page.navigate", timeout=timeout, url=url)

    def evaluate(self, expression: str, timeout: float = 30.0) -> Any:
        """The value of a JavaScript expression (promises awaited); BrowserError on an exception."""
        result = self.call(
            "Runtime.evaluate", timeout=timeout, expression=expression, returnByValue=True, awaitPromise=True
        )
        if "exceptionDetails" in result:
            details = result["exceptionDetails"]
            text = details.get("exception", {}).get("description") or details.get("text")
            raise BrowserError(f"JavaScript error: {text}")
        return result.get("result", {}).get("value")

    def wait_for(self, expression: str, timeout: float = 30.0, interval: float = 0.1) -> Any:
        """Poll until the expression is truthy; its value. BrowserError with the last value on timeout."""
        deadline = time.monotonic() + timeout
        value = None
        while time.monotonic() < deadline:
            try:
                value = self.evaluate(expression)
            except BrowserError as exc:  # e.g. the page is between two documents
                value = str(exc)
            else:
                if value:
                    return value
            time.sleep(interval)
        raise BrowserError(f"timed out after {timeout} s waiting for {expression!r} (last value {value!r})")

    def screenshot(self) -> bytes:
        """PNG of the page's viewport, in CSS pixels (device scale factor 1)."""
        return base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])

    def click(self, x: float, y: float) -> None:
        """A real mouse click (press and release) at viewport coordinates."""
        for kind in ("mousePressed", "mouseReleased"):
            self.call("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left", clickCount=1)

    def tap(self, x: float, y: float) -> None:
        """A touch tap at viewport coordinates (what a tablet does)."""
        self.call("Input.dispatchTouchEvent", type="touchStart", touchPoints=[{"x": x, "y": y}])
        self.call("Input.dispatchTouchEvent", type="touchEnd", touchPoints=[])

    def center_of(self, selector: str) -> tuple[float, float]:
        box = self.evaluate(
            f"(() => {{ const r = document.querySelector({json.dumps(selector)}).getBoundingClientRect();"
            " return [r.x + r.width / 2, r.y + r.height / 2]; })()"
        )
        return float(box[0]), float(box[1])

    # ------------------------------------------------------------------ shutdown

    def close(self) -> None:
        async def _close() -> None:
            if self._ws is not None:
                await self._ws.close()
            if self._http is not None:
                await self._http.close()

        try:
            if self._loop.is_running():
                self._run(_close(), timeout=5.0)
        except Exception:
            pass
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGTERM)
                self.proc.wait(5.0)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                pass
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)  # helpers of the group that outlived the browser
        except (ProcessLookupError, PermissionError):
            pass
        if self.proc.poll() is None:
            self.proc.wait(5.0)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(5.0)
        if not self._thread.is_alive():
            self._loop.close()
        self._log.close()
        shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
