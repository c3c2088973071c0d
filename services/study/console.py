"""The experimenter's console: a small local web page showing the trial live, with its controls.

``GET /?token=T`` serves the page (``static/console.html``) and sets the token as a cookie
(HttpOnly, SameSite=Strict, named after the port so two consoles on one machine do not clash); its
script and style (``/static/...``) and ``GET /api/state`` (the trial's progress as JSON, polled
once a second) need the token too, as that cookie, the ``token`` query parameter or an
``X-Console-Token`` header. ``POST /api/<command>`` with a JSON body — ``mark`` {note}, ``pause``,
``resume``, ``door`` {door, open} (a real world only), ``abort`` {reason}, ``end`` (after the
mission, without the questionnaire) — hands the command to the trial and answers with what it did,
or 409 and why not.

Who may use it: it listens on 127.0.0.1 by default (``--console-host`` to change that; it speaks
plain HTTP, so only on a network you trust), and every request needs this run's random token,
compared in constant time: another user of the machine, or a web page in the experimenter's browser
(DNS rebinding, cross-site requests), cannot drive the trial. POSTs must also be JSON (a cross-site
form cannot send that without the browser asking first) and, when the browser says where it comes
from (``Origin``), come from the console's own origin. Every response carries a strict Content
Security Policy: scripts and styles only from the console's own static files, nothing inline.

The server runs on an asyncio loop of its own thread; commands reach the trial through
:meth:`~.trial.TrialRun.submit`, which runs them on the runner's worker.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import hmac
import json
import logging
import secrets
import threading
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from aiohttp import web

log = logging.getLogger("arroch.study.console")

STATIC = Path(__file__).parent / "static"
TOKEN_BYTES = 18
COMMANDS = ("mark", "pause", "resume", "door", "abort", "end")
COMMAND_TIMEOUT = 5.0  # seconds the console waits for the trial to take a command
MAX_BODY = 4096
SECURITY_HEADERS = {
    "Content-Security-Policy": (
        "default-src 'none'; script-src 'self'; style-src 'self'; connect-src 'self'; img-src 'self'; "
        "base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
    ),
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
    "X-Frame-Options": "DENY",
    "Cross-Origin-Opener-Policy": "same-origin",
    "Cross-Origin-Resource-Policy": "same-origin",
}
CONTENT_TYPES = {".html": "text/html", ".js": "text/javascript", ".css": "text/css"}
HEADER = "X-Console-Token"

Submit = Callable[..., concurrent.futures.Future]


class Console:
    """The console's web server for one trial."""

    def __init__(
        self,
        snapshot: Callable[[], dict[str, Any]],
        submit: Submit,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        token: str | None = None,
    ) -> None:
        self.snapshot = snapshot
        self.submit = submit
        self.host = host
        self.port = port
        self.token = token or secrets.token_urlsafe(TOKEN_BYTES)
        self.cookie = "arroch_console"
        self.refused = 0
        self._static = {p.name: p for p in STATIC.iterdir() if p.suffix in CONTENT_TYPES}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._runner: web.AppRunner | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None

    @property
    def url(self) -> str:
        shown = f"[{self.host}]" if ":" in self.host else self.host
        if self.host in ("0.0.0.0", "::", ""):
            shown = "127.0.0.1"
        return f"http://{shown}:{self.port}/?token={self.token}"

    # ------------------------------------------------------------------ life

    def start(self, timeout: float = 10.0) -> str:
        """Serve on a thread of its own; returns the URL (with the token). OSError if it cannot listen."""
        self._thread = threading.Thread(target=self._serve, name="study-console", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise OSError(f"the console did not start within {timeout:.0f} s")
        if self._error is not None:
            raise OSError(f"the console cannot listen on {self.host}:{self.port}: {self._error}")
        return self.url

    def _serve(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(self._open())
        except Exception as exc:  # the port is taken, the address is wrong: start() says so
            self._error = exc
            self._ready.set()
            loop.close()
            return
        self._ready.set()
        try:
            loop.run_forever()
        finally:
            loop.run_until_complete(self._close())
            loop.close()

    async def _open(self) -> None:
        self._runner = web.AppRunner(self._app(), access_log=None, handle_signals=False)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.port)
        await site.start()
        server = site._server  # aiohttp keeps the listening sockets there; the port is needed with port 0
        sockets = getattr(server, "sockets", None) or []
        if sockets:
            self.port = int(sockets[0].getsockname()[1])
        self.cookie = f"arroch_console_{self.port}"

    async def _close(self) -> None:
        if self._runner is not None:
            await self._runner.cleanup()

    def stop(self) -> None:
        if self._loop is not None and self._thread is not None and self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(5.0)

    # ------------------------------------------------------------------ app

    def _app(self) -> web.Application:
        app = web.Application(client_max_size=MAX_BODY, middlewares=[self._headers])
        app.router.add_get("/", self._index)
        app.router.add_get("/static/{name}", self._asset)
        app.router.add_get("/api/state", self._state)
        app.router.add_post("/api/{command}", self._command)
        return app

    @web.middleware
    async def _headers(
        self, request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]
    ) -> web.StreamResponse:
        try:
            response = await handler(request)
        except web.HTTPException as exc:  # 404 and the like carry the headers too
            exc.headers.update(SECURITY_HEADERS)
            raise
        response.headers.update(SECURITY_HEADERS)
        return response

    def _authorised(self, request: web.Request) -> bool:
        """The token as query parameter, header or cookie (the one given first counts)."""
        if "token" in request.query:
            candidate = request.query.get("token")
        elif HEADER in request.headers:
            candidate = request.headers.get(HEADER)
        else:
            candidate = request.cookies.get(self.cookie)
        if candidate is not None and hmac.compare_digest(candidate.encode("utf-8", "replace"), self.token.encode()):
            return True
        self.refused += 1
        if self.refused <= 10 or self.refused % 100 == 0:
            log.warning(
                "console: refused %s %s from %s: missing or wrong token (%d refused)",
                request.method,
                request.path,
                request.remote,
                self.refused,
            )
        return False

    @staticmethod
    def _forbidden() -> web.Response:
        return web.Response(status=403, text="403 Forbidden: open the console URL the runner printed\n")

    async def _index(self, request: web.Request) -> web.StreamResponse:
        if not self._authorised(request):
            return self._forbidden()
        response = web.Response(body=self._static["console.html"].read_bytes(), content_type="text/html")
        response.set_cookie(self.cookie, self.token, httponly=True, samesite="Strict", path="/")
        return response

    async def _asset(self, request: web.Request) -> web.StreamResponse:
        if not self._authorised(request):
            return self._forbidden()
        path = self._static.get(request.match_info["name"])
        if path is None or path.suffix == ".html":
            raise web.HTTPNotFound()
        return web.Response(body=path.read_bytes(), content_type=CONTENT_TYPES[path.suffix])

    async def _state(self, request: web.Request) -> web.StreamResponse:
        if not self._authorised(request):
            return self._forbidden()
        return web.json_response(self.snapshot())

    async def _command(self, request: web.Request) -> web.StreamResponse:
        if not self._authorised(request):
            return self._forbidden()
        origin = request.headers.get("Origin")
        if origin is not None and origin != f"{request.scheme}://{request.host}":
            log.warning("console: refused %s from origin %r (not the console's)", request.path, origin)
            return web.json_response({"ok": False, "error": "origin not allowed"}, status=403)
        command = request.match_info["command"]
        if command not in COMMANDS:
            raise web.HTTPNotFound()
        if request.content_type != "application/json":
            return web.json_response({"ok": False, "error": "send JSON (Content-Type: application/json)"}, status=415)
        try:
            body = await request.json() if request.can_read_body else {}
        except (json.JSONDecodeError, UnicodeDecodeError):
            return web.json_response({"ok": False, "error": "the body is not JSON"}, status=400)
        if not isinstance(body, dict):
            return web.json_response({"ok": False, "error": "the body is a JSON object"}, status=400)
        args = {k: body[k] for k in ("note", "reason", "door", "open") if k in body}
        future = self.submit(command, **args)
        try:
            result = await asyncio.wait_for(asyncio.wrap_future(future), COMMAND_TIMEOUT)
        except TimeoutError:
            future.cancel()
            return web.json_response({"ok": False, "error": "the trial did not answer in time"}, status=503)
        except Exception as exc:  # CommandRefused, or the trial gone
            return web.json_response({"ok": False, "error": str(exc)}, status=409)
        log.info("console: %s %s", command, json.dumps(args) if args else "")
        return web.json_response({"ok": True, **result})
