"""The tablet web server: the page over HTTPS, one WebSocket per page, the Zenoh bridge behind them.

Routes (every one needs the run's access token, see :mod:`.security`):

- ``GET /`` the page (``static/index.html``); sets the token cookie so its assets and socket need
  no token in their URLs. ``?mode=viewer`` shows the sim's stream and the map instead of the camera.
- ``GET /static/<file>`` the page's scripts and style (only the files shipped in ``static/``).
- ``GET /ca.pem`` the authority that signed the server's certificate, to install on a tablet.
- ``GET /ws`` the WebSocket (:mod:`.session`); also checks the Origin and the number of clients.
- ``GET /puzzle.png`` in study mode (``--study-trial``): the puzzle's picture, drawn from the trial's seed.

Study mode (:mod:`.study`): the trial file decides what the page is (the study page of its
condition); the server keeps the trial's state, judges the page's requests and records them on
Zenoh; a page's ``?questionnaire=1`` lets the experimenter open the questionnaire early.

Threads: the event loop (HTTP, WebSockets, periodic world updates) on the main thread; the bridge's
Zenoh worker; ``--workers`` frame threads running the AR pipelines (OpenCV releases the GIL); two
feedback threads (a feedback waits for the restrictor's ack). Responses carry a strict Content
Security Policy, ``no-store`` and ``no-referrer`` (the token must not leak in a Referer header);
the access log is off, since URLs carry the token.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from collections.abc import Awaitable, Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from aiohttp import web

from protocol.messages import (
    CameraFrame,
    Clock,
    ConstraintSet,
    Event,
    HumanState,
    Overlay,
    ParticipantAction,
    QuestionnaireAnswers,
)

from ..detect import TagDetector
from ..overlay import OverlayBuilder
from ..pipeline import BadFrame, Pipeline
from ..project import Intrinsics
from . import wire
from .bridge import TabletBridge
from .intrinsics import CameraModel
from .puzzle_picture import picture_png
from .security import COOKIE, origin_allowed, token_matches
from .session import ClientSession
from .study import StudyController
from .study_store import ProgressStore
from .study_trial import StudyTrial
from .study_wire import StudyMessage

log = logging.getLogger("arroch.tablet")

STATIC = Path(__file__).parent / "static"
WORLD_PERIOD = 0.25  # seconds between map updates
VIOLATION_LOG_PER_MINUTE = 20
SECURITY_HEADERS = {
    "Content-Security-Policy": (
        "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; "
        "media-src 'self' blob: mediastream:; connect-src 'self'; base-uri 'none'; form-action 'none'; "
        "frame-ancestors 'none'"
    ),
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
    "X-Frame-Options": "DENY",
    "Cross-Origin-Opener-Policy": "same-origin",
}
CONTENT_TYPES = {".html": "text/html", ".js": "text/javascript", ".css": "text/css", ".svg": "image/svg+xml"}
REFUSAL_LOG_PER_MINUTE = 20


@dataclass
class ServerOptions:
    max_fps: float = 15.0
    max_clients: int = 8
    workers: int = 2
    detector: str = "opencv"
    allow_origins: list[str] = field(default_factory=list)
    default_mode: str = "ar"  # the page's mode when its URL does not say
    study: StudyTrial | None = None  # --study-trial: the page is this trial's study page
    study_progress: Path | None = None  # where the trial's progress is saved (None: memory only)


class TabletServer:
    def __init__(
        self,
        *,
        site,
        bridge: TabletBridge,
        camera_model: CameraModel,
        token: str,  # noqa: ANN001 (Site)
        authority: Path | None = None,
        options: ServerOptions | None = None,
    ) -> None:
        self.site = site
        self.bridge = bridge
        self.camera_model = camera_model
        self.token = token
        self.authority = authority
        self.options = options or ServerOptions()
        self.frame_pool = ThreadPoolExecutor(max_workers=self.options.workers, thread_name_prefix="tablet-frame")
        self.feedback_pool = ThreadPoolExecutor(max_workers=2, thread_name_prefix="tablet-feedback")
        self.clients: dict[int, ClientSession] = {}
        self.colours = OverlayBuilder(site)  # the robots' overlay colours, for the map
        self.counters: dict[str, int] = {
            "connections": 0,
            "refused_token": 0,
            "refused_origin": 0,
            "refused_full": 0,
            "violations": 0,
            "study_refused": 0,
        }
        self._numbers = 0
        self._violation_log: list[float] = []
        self._loop: asyncio.AbstractEventLoop | None = None
        self._world_task: asyncio.Task | None = None
        self._last_world = ""
        self._sim_frame: CameraFrame | None = None
        self._viewer_busy = False
        self._viewer_pipeline: Pipeline | None = None
        self._static = {p.name: p for p in STATIC.iterdir() if p.suffix in CONTENT_TYPES}
        self._refusal_log: list[float] = []
        self.study: StudyController | None = None
        self._puzzle_png = b""
        trial = self.options.study
        if trial is not None:
            self.study = StudyController(
                trial,
                publish_action=self._publish_record,
                publish_answers=self._publish_record,
                store=ProgressStore(self.options.study_progress),
            )
            self._puzzle_png = picture_png(trial.puzzle.seed, trial.puzzle.rows, trial.puzzle.cols)
        self.app = self._make_app()

    # ------------------------------------------------------------------ app

    def _make_app(self) -> web.Application:
        app = web.Application(client_max_size=64 * 1024, middlewares=[self._headers])
        app.router.add_get("/", self._index)
        app.router.add_get("/static/{name}", self._asset)
        app.router.add_get("/ca.pem", self._ca)
        app.router.add_get("/ws", self._websocket)
        app.router.add_get("/puzzle.png", self._puzzle)
        app.on_startup.append(self._on_startup)
        app.on_shutdown.append(self._on_shutdown)
        return app

    @web.middleware
    async def _headers(
        self, request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]
    ) -> web.StreamResponse:
        try:
            response = await handler(request)
        except web.HTTPException as exc:
            response = exc
        if not response.prepared:  # a WebSocket's handshake is already sent
            response.headers.update(SECURITY_HEADERS)
        return response

    def _authorised(self, request: web.Request) -> bool:
        if token_matches(self.token, request.query, request.cookies):
            return True
        self.counters["refused_token"] += 1
        log.warning(
            "refused %s %s from %s: missing or wrong access token", request.method, request.path, request.remote
        )
        return False

    @staticmethod
    def _forbidden(why: str) -> web.Response:
        return web.Response(status=403, text=f"403 Forbidden: {why}\n")

    async def _index(self, request: web.Request) -> web.StreamResponse:
        if not self._authorised(request):
            return self._forbidden("missing or wrong access token (open the URL the server printed)")
        response = web.Response(body=self._static["index.html"].read_bytes(), content_type="text/html")
        response.set_cookie(COOKIE, self.token, secure=True, httponly=True, samesite="Strict", path="/")
        return response

    async def _asset(self, request: web.Request) -> web.StreamResponse:
        if not self._authorised(request):
            return self._forbidden("missing or wrong access token")
        path = self._static.get(request.match_info["name"])
        if path is None or path.name == "index.html":
            raise web.HTTPNotFound()
        return web.Response(body=path.read_bytes(), content_type=CONTENT_TYPES[path.suffix])

    async def _ca(self, request: web.Request) -> web.StreamResponse:
        if not self._authorised(request):
            return self._forbidden("missing or wrong access token")
        if self.authority is None or not self.authority.exists():
            raise web.HTTPNotFound()
        return web.Response(body=self.authority.read_bytes(), content_type="application/x-pem-file")

    async def _puzzle(self, request: web.Request) -> web.StreamResponse:
        if not self._authorised(request):
            return self._forbidden("missing or wrong access token")
        if self.study is None:
            raise web.HTTPNotFound()
        return web.Response(body=self._puzzle_png, content_type="image/png")

    async def _websocket(self, request: web.Request) -> web.StreamResponse:
        if not self._authorised(request):
            return self._forbidden("missing or wrong access token")
        origin = request.headers.get("Origin")
        if not origin_allowed(origin, request.host, request.scheme, self.options.allow_origins):
            self.counters["refused_origin"] += 1
            log.warning(
                "refused a WebSocket from %s: origin %r is not this page's (%s://%s)",
                request.remote,
                origin,
                request.scheme,
                request.host,
            )
            return self._forbidden("origin not allowed")
        if len(self.clients) >= self.options.max_clients:
            self.counters["refused_full"] += 1
            return web.Response(status=503, text=f"503: at most {self.options.max_clients} pages at once\n")
        if self.study is not None:
            # The trial decides, never the page: the sim's stream (AR conditions) or the map alone.
            mode = "map" if self.study.trial.robots_view == "map" else "viewer"
        else:
            mode = request.query.get("mode", self.options.default_mode)
            if mode not in ("ar", "viewer"):
                return web.Response(status=400, text="400: mode is ar or viewer\n")
        # max_msg_size: aiohttp itself refuses (close 1009) anything larger than a frame can be.
        ws = web.WebSocketResponse(max_msg_size=wire.MAX_FRAME_BYTES + wire.HEADER.size, heartbeat=15.0, compress=False)
        await ws.prepare(request)
        self._numbers += 1
        session = ClientSession(self, ws, self._numbers, mode, str(request.remote))
        session.early_questionnaire = self.study is not None and request.query.get("questionnaire") == "1"
        self.clients[session.number] = session
        self.counters["connections"] += 1
        log.info("client %d connected from %s (%s mode)", session.number, request.remote, mode)
        try:
            await session.run()
        finally:
            self.clients.pop(session.number, None)
            log.info(
                "client %d disconnected (%d frames, %d superseded, %d feedback)",
                session.number,
                session.counters["frames"],
                session.counters["superseded"],
                session.counters["feedback"],
            )
        return ws

    # ------------------------------------------------------------------ study mode

    def _publish_record(self, msg: ParticipantAction | QuestionnaireAnswers) -> None:
        """Publish a participant's action or answers (the event loop; a Zenoh put does not block long)."""
        try:
            if isinstance(msg, QuestionnaireAnswers):
                self.bridge.publish_answers(msg)
            else:
                self.bridge.publish_action(msg)
        except Exception as exc:  # Zenoh closing under us: the log keeps what could not be sent
            log.error("could not publish %s: %s (%s)", msg.TYPE, exc, msg)

    async def study_request(self, session: ClientSession, message: StudyMessage) -> None:
        """A study page's request: judged by the trial; a refusal goes back to that page only."""
        if self.study is None:  # the session refuses study messages first; nothing to judge here
            return
        outcome = self.study.handle(message, early_questionnaire=session.early_questionnaire)
        if outcome.refused is not None:
            what = {v: k for k, v in wire.PAGE_MESSAGES.items()}.get(type(message), "request")
            self.note_refusal(session, what, outcome.refused)
            await session.send_text(json.dumps({"type": "refused", "what": what, "reason": outcome.refused}))
        if outcome.changed:
            await self.broadcast_study()

    def study_feedback(self, session: ClientSession, kind: str, params: dict[str, Any], wall: float) -> str | None:
        """Record a study page's feedback; why it is refused in this trial, or None (send it on)."""
        if self.study is None:
            return None
        refused = self.study.feedback(kind, params, wall or time.time())
        if refused is not None:
            self.note_refusal(session, "feedback", refused)
        return refused

    def note_refusal(self, session: ClientSession, what: str, reason: str) -> None:
        """Count a study request turned down (the page stays connected); log it unless many were logged."""
        self.counters["study_refused"] += 1
        self.bridge.count("study_refused")  # in the tablet's stats on Zenoh, with one count per kind
        self.bridge.count(f"study_refused_{what}")
        now = time.monotonic()
        self._refusal_log = [t for t in self._refusal_log if now - t < 60.0]
        if len(self._refusal_log) < REFUSAL_LOG_PER_MINUTE:
            self._refusal_log.append(now)
            log.warning("client %d (%s): %s refused: %s", session.number, session.remote, what, reason)

    async def broadcast_study(self) -> None:
        if self.study is not None:
            await self._broadcast(json.dumps(self.study.page_state(), separators=(",", ":")))

    def _human_state(self, msg: HumanState) -> None:
        if self.study is not None and self.study.human_changed(msg):
            asyncio.get_running_loop().create_task(self.broadcast_study())

    def _clock(self, msg: Clock) -> None:
        if self.study is not None and self.study.clock_changed(msg):
            asyncio.get_running_loop().create_task(self.broadcast_study())

    def _mission_done(self, msg: Event) -> None:
        if self.study is not None and self.study.mission_ended():
            asyncio.get_running_loop().create_task(self.broadcast_study())

    def note_violation(self, session: ClientSession, reason: str) -> None:
        """Count a client's protocol violation; log it unless many were logged this minute."""
        self.counters["violations"] += 1
        now = time.monotonic()
        self._violation_log = [t for t in self._violation_log if now - t < 60.0]
        if len(self._violation_log) < VIOLATION_LOG_PER_MINUTE:
            self._violation_log.append(now)
            log.warning("client %d (%s): %s; disconnecting it", session.number, session.remote, reason)

    # ------------------------------------------------------------------ what pages get

    def hello(self, session: ClientSession) -> dict[str, Any]:
        return {
            "type": "hello",
            "client": session.number,
            "camera": session.camera_id,
            "mode": session.mode,
            "stream": self.bridge.sim_camera,
            "max_fps": self.options.max_fps,
            "max_side": wire.MAX_SIDE,
            "max_frame_bytes": wire.MAX_FRAME_BYTES,
            "site": wire.site_json(self.site),
            "library": self.bridge.library,  # None until a restrictor answers: then a "library" message
            "constraints": self._constraints_json(self.bridge.constraints),
            "world": self._world(),
            "study": self.study.hello_state() if self.study is not None else None,
        }

    @staticmethod
    def _constraints_json(msg: ConstraintSet | None) -> dict[str, Any]:
        if msg is None:
            return {"type": "constraints", "version": None, "items": []}
        items = [
            {"id": c.id, "kind": c.kind, "params": c.params, "start": c.start, "end": c.end} for c in msg.constraints
        ]
        return {"type": "constraints", "version": msg.version, "items": items}

    def _world(self) -> dict[str, Any]:
        world = wire.world_json(self.bridge.world.snapshot(self.bridge.now()), self.colours.colour)
        human = self.study.human if self.study is not None else None
        if human is not None:  # where the simulator has her, for the map (her desk otherwise)
            world["human"] = [round(human.x, 3), round(human.y, 3), round(human.theta, 3)]
        return world

    def new_pipeline(self, camera_id: str) -> Pipeline:
        detector = TagDetector(self.options.detector, known_ids=[lm.tag for lm in self.site.landmarks])
        return Pipeline(self.site, self.bridge.world, camera_id=camera_id, detector=detector)

    def publish_overlay(self, overlay: Overlay, reason: str) -> None:
        try:
            self.bridge.publish_overlay(overlay, reason)
        except Exception as exc:  # Zenoh closing during shutdown: the page still gets its overlay
            log.debug("could not publish an overlay: %s", exc)

    async def _broadcast(self, text: str, *, mode: str | None = None) -> None:
        sends = [
            c.send_text(text)
            for c in list(self.clients.values())
            if (mode is None or c.mode == mode) and not c.busy_sending
        ]
        if sends:
            await asyncio.gather(*sends)

    async def _world_updates(self) -> None:
        while True:
            await asyncio.sleep(WORLD_PERIOD)
            if not self.clients:
                continue
            try:
                world = self._world()
            except Exception:
                log.exception("building the map update failed")
                continue
            # The robots, intents and doors, not the time, decide whether the map changed.
            state = json.dumps({k: v for k, v in world.items() if k != "now"}, separators=(",", ":"))
            if state == self._last_world:
                continue
            self._last_world = state
            await self._broadcast(json.dumps(world, separators=(",", ":")))

    # ------------------------------------------------------------------ callbacks from the bridge (Zenoh worker thread)

    def _from_worker(self, fn: Callable[..., Any], *args: Any) -> None:
        loop = self._loop
        if loop is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(fn, *args)
            except RuntimeError:  # the loop closed in between: shutting down
                pass

    def _constraints_changed(self, msg: ConstraintSet) -> None:
        text = json.dumps(self._constraints_json(msg), separators=(",", ":"))
        asyncio.get_running_loop().create_task(self._broadcast(text))

    def _library_arrived(self, entries: list[dict[str, Any]]) -> None:
        text = json.dumps({"type": "library", "entries": entries}, separators=(",", ":"))
        asyncio.get_running_loop().create_task(self._broadcast(text))

    def _sim_frame_arrived(self, msg: CameraFrame) -> None:
        self._sim_frame = msg
        if not self._viewer_busy and any(c.wants_stream for c in self.clients.values()):
            self._viewer_busy = True
            asyncio.get_running_loop().create_task(self._viewer_frames())

    async def _viewer_frames(self) -> None:
        """Process the newest sim frame for the viewer pages, one at a time, until none is new."""
        loop = asyncio.get_running_loop()
        try:
            while self._sim_frame is not None:
                msg, self._sim_frame = self._sim_frame, None
                try:
                    text = await loop.run_in_executor(self.frame_pool, self._localise_sim_frame, msg)
                except (BadFrame, wire.Violation) as exc:
                    self.bridge.count("bad_sim_frames")
                    log.debug("sim frame %s/%d dropped: %s", msg.src, msg.seq, exc)
                    continue
                viewers = [c for c in self.clients.values() if c.wants_stream and not c.busy_sending]
                if viewers:
                    image = wire.pack_frame(msg.seq, msg.jpeg, wire.VIEWER_MAGIC)
                    await asyncio.gather(*(self._send_viewer(c, image, text) for c in viewers))
        finally:
            self._viewer_busy = False

    @staticmethod
    async def _send_viewer(client: ClientSession, image: bytes, text: str) -> None:
        await client.send_bytes(image)
        await client.send_text(text)

    def _localise_sim_frame(self, msg: CameraFrame) -> str:
        started = time.perf_counter()
        width, height = wire.jpeg_size(msg.jpeg)
        if (
            (width, height) != (msg.width, msg.height)
            or len(msg.intrinsics) != 4
            or not np.all(np.isfinite(msg.intrinsics))
            or msg.intrinsics[0] <= 0
            or msg.intrinsics[1] <= 0
        ):
            raise BadFrame(f"frame {width}x{height} with intrinsics {msg.intrinsics} for {msg.width}x{msg.height}")
        fx, fy, cx, cy = msg.intrinsics
        distortion = tuple(msg.distortion) if len(msg.distortion) == 5 else (0.0,) * 5
        K = Intrinsics(fx, fy, cx, cy, msg.width, msg.height, distortion)
        if self._viewer_pipeline is None:
            self._viewer_pipeline = self.new_pipeline(msg.camera)
        now = self.bridge.now()
        gravity = msg.gravity or None
        overlay, _ = self._viewer_pipeline.process(
            msg.jpeg, K, now, frame_seq=msg.seq, annotate=False, now=now, gravity=gravity
        )
        loc = self._viewer_pipeline.last_localization
        reason = loc.reason if loc is not None and not loc.ok else ""
        return wire.overlay_json(
            overlay,
            reason=reason,
            intrinsics="from the sim camera",
            source="sim",
            server_ms=(time.perf_counter() - started) * 1000.0,
            gravity=gravity,
        )

    # ------------------------------------------------------------------ lifecycle

    async def _on_startup(self, app: web.Application) -> None:
        self._loop = asyncio.get_running_loop()
        self.bridge.on_constraints = lambda msg: self._from_worker(self._constraints_changed, msg)
        self.bridge.on_library = lambda entries: self._from_worker(self._library_arrived, entries)
        self.bridge.on_sim_frame = lambda msg: self._from_worker(self._sim_frame_arrived, msg)
        self.bridge.on_human_state = lambda msg: self._from_worker(self._human_state, msg)
        self.bridge.on_clock = lambda msg: self._from_worker(self._clock, msg)
        self.bridge.on_mission_done = lambda msg: self._from_worker(self._mission_done, msg)
        self._world_task = self._loop.create_task(self._world_updates())

    async def _on_shutdown(self, app: web.Application) -> None:
        if self._world_task is not None:
            self._world_task.cancel()
        self.bridge.on_constraints = lambda msg: None
        self.bridge.on_library = lambda entries: None
        self.bridge.on_sim_frame = lambda msg: None
        self.bridge.on_human_state = lambda msg: None
        self.bridge.on_clock = lambda msg: None
        self.bridge.on_mission_done = lambda msg: None
        for client in list(self.clients.values()):
            await client.ws.close(code=1001, message=b"server stopping")

    def close_pools(self) -> None:
        self.frame_pool.shutdown(wait=True, cancel_futures=True)
        self.feedback_pool.shutdown(wait=False, cancel_futures=True)
