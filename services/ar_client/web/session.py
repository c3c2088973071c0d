"""One page's WebSocket: frames in, that frame's overlay out; feedback in, its ack out.

Each page (client) has its own :class:`~services.ar_client.pipeline.Pipeline` — tracking state
belongs to one camera — built on its first frame. Frames are localised on the server's frame
threads; at most one frame per client is processed at a time and at most one waits (a newer frame
replaces a waiting one, counted as ``superseded``), so a slow client never queues up stale work and
reading its socket never stops (feedback is answered while a frame is processed).

Anything that breaks :mod:`.wire`'s protocol, or a message rate above the limits, closes this
client's socket with the matching close code; other clients are not affected. A study page's
well-formed requests go to the server's study (:meth:`TabletServer.study_request`), which may refuse
them with a reason: the socket stays open.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from typing import TYPE_CHECKING, Any

from aiohttp import WSMsgType, web

from ..pipeline import BadFrame, Pipeline
from . import wire
from .security import TokenBucket
from .study_wire import STUDY_MESSAGES, ViewChange
from .wire import Frame, Violation

if TYPE_CHECKING:
    from .server import TabletServer

log = logging.getLogger("arroch.tablet.session")

#: Messages of any kind a page may send per second (sustained; twice that at once).
MESSAGE_RATE = 60.0
#: Feedback requests a page may send per minute (sustained; 5 at once).
FEEDBACK_PER_MINUTE = 20.0


class ClientSession:
    def __init__(self, server: TabletServer, ws: web.WebSocketResponse, number: int, mode: str, remote: str) -> None:
        self.server = server
        self.ws = ws
        self.number = number
        self.camera_id = f"tablet-{number}"
        self.mode = mode  # "ar" (the page's camera), "viewer" (the sim's stream and the map), "map" (study: map only)
        self.early_questionnaire = False  # study: the experimenter opened this page with ?questionnaire=1
        self.watching = False  # study: the page shows the robots' AR view (it gets the sim's stream only then)
        self.remote = remote
        self.pipeline: Pipeline | None = None
        self.counters: dict[str, int] = {"frames": 0, "superseded": 0, "feedback": 0}
        self._messages = TokenBucket(MESSAGE_RATE, 2 * MESSAGE_RATE)
        self._frames = TokenBucket(2.0 * server.options.max_fps, 2.0 * server.options.max_fps)
        self._feedback = TokenBucket(FEEDBACK_PER_MINUTE / 60.0, 5.0)
        self._processing = False
        self._waiting: Frame | None = None
        self._feedback_pending = False
        self._send_lock = asyncio.Lock()
        self._tasks: set[asyncio.Task] = set()
        self.closed = False

    # ------------------------------------------------------------------ sending

    @property
    def wants_stream(self) -> bool:
        """The sim's frames are for this page: a viewer page, and on a study page only while its AR view shows."""
        return self.mode == "viewer" and (self.server.study is None or self.watching)

    @property
    def busy_sending(self) -> bool:
        """A send is under way (the link is slow): periodic updates skip this client for now."""
        return self._send_lock.locked()

    async def send_text(self, text: str) -> None:
        await self._send(self.ws.send_str, text)

    async def send_bytes(self, data: bytes) -> None:
        await self._send(self.ws.send_bytes, data)

    async def _send(self, method, payload) -> None:  # noqa: ANN001
        if self.closed or self.ws.closed:
            return
        async with self._send_lock:
            try:
                await method(payload)
            except (ConnectionError, RuntimeError) as exc:  # the peer went away mid-send
                log.debug("client %d: send failed: %s", self.number, exc)

    def _spawn(self, coro) -> None:  # noqa: ANN001
        task = asyncio.get_running_loop().create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    # ------------------------------------------------------------------ the receive loop

    async def run(self) -> None:
        await self.send_text(json.dumps(self.server.hello(self), separators=(",", ":")))
        try:
            async for msg in self.ws:
                if not self._messages.take():
                    raise Violation(wire.CLOSE_POLICY, f"more than {MESSAGE_RATE:g} messages per second")
                if msg.type == WSMsgType.BINARY:
                    self._on_frame(msg.data)
                elif msg.type == WSMsgType.TEXT:
                    self._on_text(msg.data)
                elif msg.type == WSMsgType.ERROR:
                    # aiohttp reports an oversized or malformed WebSocket frame this way, then closes.
                    self.server.note_violation(self, f"WebSocket error: {self.ws.exception()}")
                    break
        except Violation as exc:
            self.server.note_violation(self, exc.reason)
            await self.ws.close(code=exc.code, message=exc.reason[:120].encode())
        finally:
            self.closed = True
            for task in list(self._tasks):
                task.cancel()

    def _on_text(self, text: str) -> None:
        message = wire.parse_text(text)
        if isinstance(message, wire.FeedbackRequest):
            self._spawn(self._on_feedback(message))
        elif isinstance(message, tuple(STUDY_MESSAGES.values())):
            if self.server.study is None:
                raise Violation(wire.CLOSE_POLICY, "a study message to a server that runs no study (no --study-trial)")
            if isinstance(message, ViewChange):
                self.watching = message.view == "ar" and message.note != "hidden"
            self._spawn(self.server.study_request(self, message))
        else:
            self._spawn(self.send_text(json.dumps({"type": "pong", "t": message.t})))

    # ------------------------------------------------------------------ frames

    def _on_frame(self, data: bytes) -> None:
        if self.mode != "ar":
            raise Violation(wire.CLOSE_POLICY, "a viewer page sends no frames")
        if not self._frames.take():
            raise Violation(wire.CLOSE_POLICY, f"more than {2 * self.server.options.max_fps:g} frames per second")
        frame = wire.parse_frame(data)
        self.counters["frames"] += 1
        if self._processing:
            if self._waiting is not None:
                self.counters["superseded"] += 1
            self._waiting = frame
            return
        self._processing = True
        self._spawn(self._process_frames(frame))

    async def _process_frames(self, frame: Frame | None) -> None:
        loop = asyncio.get_running_loop()
        try:
            while frame is not None and not self.closed:
                try:
                    text = await loop.run_in_executor(self.server.frame_pool, self._localise, frame)
                except BadFrame as exc:
                    self.server.note_violation(self, f"undecodable frame: {exc}")
                    await self.ws.close(code=wire.CLOSE_UNSUPPORTED, message=b"undecodable frame")
                    return
                await self.send_text(text)
                frame, self._waiting = self._waiting, None
        finally:
            self._processing = False

    def _localise(self, frame: Frame) -> str:
        """Frame thread: localise one frame and draw the world for it; the page's overlay message."""
        started = time.perf_counter()
        if self.pipeline is None:
            self.pipeline = self.server.new_pipeline(self.camera_id)
        intrinsics, source = self.server.camera_model.for_size(frame.width, frame.height)
        now = self.server.bridge.now()
        overlay, _ = self.pipeline.process(
            frame.jpeg, intrinsics, now, frame_seq=frame.seq, annotate=False, now=now, gravity=frame.gravity
        )
        loc = self.pipeline.last_localization
        reason = loc.reason if loc is not None and not loc.ok else ""
        self.server.publish_overlay(overlay, reason)
        return wire.overlay_json(
            overlay,
            reason=reason,
            intrinsics=source,
            server_ms=(time.perf_counter() - started) * 1000.0,
            gravity=frame.gravity,
        )

    # ------------------------------------------------------------------ feedback

    async def _on_feedback(self, request: wire.FeedbackRequest) -> None:
        answer: dict[str, Any] = {"type": "ack", "id": request.id, "kind": request.kind}
        if self._feedback_pending:
            answer.update(status="busy", reason="the previous feedback is still waiting for its answer")
        elif not self._feedback.take():
            answer.update(status="busy", reason="too much feedback at once; wait a moment")
        elif (refused := self.server.study_feedback(self, request.kind, request.params, request.wall)) is not None:
            answer.update(status="refused", reason=refused)
        else:
            self._feedback_pending = True
            self.counters["feedback"] += 1
            try:
                ack = await asyncio.get_running_loop().run_in_executor(
                    self.server.feedback_pool, self.server.bridge.send_feedback, request.kind, request.params
                )
            except Exception as exc:  # the Zenoh session closing under us, etc.: tell the page
                log.warning("client %d: feedback %s failed: %s", self.number, request.kind, exc)
                answer.update(status="error", reason=str(exc)[:200])
            else:
                if ack is None:
                    answer.update(status="no answer", reason="no restrictor answered in time")
                else:
                    answer.update(
                        status="accepted" if ack.accepted else "refused",
                        reason=ack.reason,
                        constraint_id=ack.constraint_id,
                        constraints_version=ack.constraints_version,
                    )
            finally:
                self._feedback_pending = False
            log.info(
                "client %d: feedback %s %s: %s %s",
                self.number,
                request.kind,
                request.params,
                answer["status"],
                answer.get("reason", ""),
            )
        await self.send_text(json.dumps(answer))
