"""Headless Chromium driven by Playwright, for the tablet, study and demo tests and the tablet benchmark.

Uses the machine's Chromium (Debian's ``chromium`` package; ``$ARROCH_CHROMIUM`` to point elsewhere),
never a browser downloaded by Playwright, with the flags that keep it off the network (no background
connections, no component updates, no sync) and a fresh profile per run. A fake camera plays a Y4M
file (:mod:`services.ar_client.web.fakecam`); the media permission prompt is answered yes.

Chromium is started here and Playwright attaches to it over CDP without its default overrides
(``no_defaults``): Playwright's own launch turns on focus emulation for every page, which keeps a page
visible whatever tab is in front, and the study page measures the time a participant spends away from
it (``visibilitychange``). The page is the browser's own first tab, sized by the window as on a tablet.

The browser runs in its own process group and :meth:`Browser.close` ends the whole group, so no
renderer or GPU helper outlives a test. Playwright's sync API delivers page events (console, page
errors, WebSocket frames) only while one of its calls runs: :meth:`Browser.wait_for` and
:meth:`Browser.pause` wait through such calls, so the lists below fill while a test waits. While a
browser is open, its thread has Playwright's event loop running: ``asyncio.run`` cannot start there
(:func:`tests.tablet.helpers.run` runs a coroutine on a thread of its own).
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tempfile
import time
from collections import deque
from pathlib import Path
from typing import Any

from playwright.sync_api import Error as PlaywrightError
from playwright.sync_api import Playwright, WebSocket, sync_playwright

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
#: How many received WebSocket text frames a browser keeps (the oldest are dropped): a page streaming
#: for minutes must not grow without bound.
KEPT_FRAMES = 10_000
START_TIMEOUT = 30.0


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


class Browser:
    """One headless Chromium with one page (:attr:`page`, a Playwright ``Page``)."""

    def __init__(
        self,
        *,
        fake_camera: str | Path | None = None,
        window: tuple[int, int] = (1280, 800),
        ignore_certificate_errors: bool = True,
        extra_flags: tuple[str, ...] = (),
    ) -> None:
        executable = chromium_path()
        if executable is None:
            raise BrowserError("no Chromium on this machine (Debian: apt-get install chromium)")
        self.profile = Path(tempfile.mkdtemp(prefix="arroch-chromium-"))
        argv = [
            executable,
            *FLAGS,
            f"--user-data-dir={self.profile}",
            "--remote-debugging-port=0",  # Chromium picks a free port and writes it to DevToolsActivePort
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
        self.log_path = self.profile / "chromium.log"
        self._log = self.log_path.open("wb")
        self.proc = subprocess.Popen(
            argv, stdin=subprocess.DEVNULL, stdout=self._log, stderr=subprocess.STDOUT, start_new_session=True
        )
        #: What the page wrote to its console, including the browser's own entries (CSP violations).
        self.console: list[str] = []
        #: Uncaught exceptions in the page.
        self.page_errors: list[str] = []
        #: Text frames the page received on its WebSockets, oldest first.
        self.ws_frames_received: deque[str] = deque(maxlen=KEPT_FRAMES)
        self._playwright: Playwright | None = None
        try:
            self._playwright = sync_playwright().start()
            self._browser = self._playwright.chromium.connect_over_cdp(
                f"http://127.0.0.1:{self._devtools_port()}", no_defaults=True, timeout=START_TIMEOUT * 1000
            )
            self.context = self._browser.contexts[0]
            self.page = self.context.pages[0]
            # For what Playwright has no call for: a touch held down (no touch emulation on this page).
            self.cdp = self.context.new_cdp_session(self.page)
        except Exception:
            self.close()
            raise
        self.page.on("console", lambda message: self.console.append(message.text))
        self.page.on("pageerror", lambda error: self.page_errors.append(str(error)))
        self.page.on("websocket", self._record_frames)

    def _devtools_port(self) -> int:
        """The DevTools port Chromium chose, once it listens (the file holds the port, then the browser's path)."""
        active = self.profile / "DevToolsActivePort"
        deadline = time.monotonic() + START_TIMEOUT
        while True:
            if self.proc.poll() is not None:
                raise BrowserError(f"Chromium exited ({self.proc.returncode}):\n{self._log_tail()}")
            lines = active.read_text().split() if active.exists() else []
            if len(lines) >= 2:  # both written: the port is whole
                return int(lines[0])
            if time.monotonic() > deadline:
                raise BrowserError(f"Chromium's DevTools endpoint did not come up:\n{self._log_tail()}")
            time.sleep(0.05)

    def _log_tail(self) -> str:
        """The end of Chromium's output (the profile that holds it is removed on close)."""
        self._log.flush()
        return self.log_path.read_text(errors="replace")[-2000:]

    def _record_frames(self, socket: WebSocket) -> None:
        def received(payload: str | bytes) -> None:
            if isinstance(payload, str):  # binary frames (the camera stream) are not kept
                self.ws_frames_received.append(payload)

        socket.on("framereceived", received)

    # ------------------------------------------------------------------ what tests use

    def navigate(self, url: str, timeout: float = 30.0) -> None:
        # "commit": the page's own scripts are waited for with wait_for, as the page loads its parts itself.
        self.page.goto(url, wait_until="commit", timeout=timeout * 1000)

    def evaluate(self, expression: str) -> Any:  # noqa: ANN401 - whatever the page returns
        """The value of a JavaScript expression (promises awaited); Playwright's Error on an exception."""
        return self.page.evaluate(expression)

    def wait_for(self, expression: str, timeout: float = 30.0, interval: float = 0.1) -> Any:  # noqa: ANN401
        """Poll until the expression is truthy; its value. BrowserError with the last value on timeout."""
        deadline = time.monotonic() + timeout
        value = None
        while time.monotonic() < deadline:
            try:
                value = self.evaluate(expression)
            except PlaywrightError as exc:  # e.g. the page is between two documents
                value = str(exc)
            else:
                if value:
                    return value
            self.pause(interval)
        raise BrowserError(f"timed out after {timeout} s waiting for {expression!r} (last value {value!r})")

    def pause(self, seconds: float) -> None:
        """Let ``seconds`` pass while Playwright delivers the page's events."""
        self.page.wait_for_timeout(seconds * 1000)

    def screenshot(self) -> bytes:
        """PNG of the page's viewport, in CSS pixels (device scale factor 1)."""
        return self.page.screenshot(type="png")

    def center_of(self, selector: str) -> tuple[float, float]:
        """The element's centre in viewport coordinates, after scrolling it to the middle of the view
        (clear of bars fixed at the page's edges)."""
        element = self.page.locator(selector).first
        element.evaluate("(node) => node.scrollIntoView({block: 'center', inline: 'center'})")
        box = element.bounding_box()
        if box is None:
            raise BrowserError(f"{selector!r} is not laid out on the page")
        return box["x"] + box["width"] / 2, box["y"] + box["height"] / 2

    def click(self, selector: str) -> None:
        """A real mouse click (press and release) at the element's centre, wherever the page draws it."""
        self.page.mouse.click(*self.center_of(selector))

    def hold_touch(self, selector: str, seconds: float) -> None:
        """Touch the element's centre, keep the finger there ``seconds``, lift it (what a tablet does)."""
        x, y = self.center_of(selector)
        self.cdp.send("Input.dispatchTouchEvent", {"type": "touchStart", "touchPoints": [{"x": x, "y": y}]})
        time.sleep(seconds)
        self.cdp.send("Input.dispatchTouchEvent", {"type": "touchEnd", "touchPoints": []})

    # ------------------------------------------------------------------ shutdown

    def close(self) -> None:
        if self._log.closed:  # closed before (a fixture and a ``with`` may both close it)
            return
        if self._playwright is not None:
            try:
                self._playwright.stop()  # also drops the CDP connection; the browser is ended below
            except PlaywrightError:  # a browser that died took its connection with it
                pass
            self._playwright = None
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
        self._log.close()
        shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
